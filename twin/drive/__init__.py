"""Discrete models of the axis drives: converter (thyristor bridge or PWM), DC motor,
current and speed loops, tachogenerator. Numerics only (numpy/numba), no MuJoCo."""
