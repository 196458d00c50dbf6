"""xy-twin: a digital twin of a two-axis CNC cross table.

Packages: ``twin.drive`` (thyristor/PWM DC drives, numerics only), ``twin.plant`` (MuJoCo
mechanics + drives), ``twin.controller`` (the CNC stack, hardware independent),
``twin.hardware`` (drivers implementing ``MachineIO``), ``twin.telemetry`` (rerun).
"""

__version__ = "0.1.0"
