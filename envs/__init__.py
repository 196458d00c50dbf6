"""Gymnasium environments for tuning xy-twin machines.

Importing ``envs`` registers the versioned ids:

* ``XYTable-GainTuning-v0`` (``envs.gain_tuning.GainTuningEnv``): one step is one test run
  with the gains the action sets; 5 runs per episode.
* ``XYTable-Servo-v0`` (``envs.servo.ServoEnv``): one step is one control period; the
  action is a residual correction added to the position regulator's output.

Use ``gymnasium.make("XYTable-GainTuning-v0", randomize=True)`` etc.; the constructor
keywords are documented in each class docstring.
"""

from gymnasium.envs.registration import register, registry

__all__ = ["GAIN_TUNING_ID", "SERVO_ID"]

GAIN_TUNING_ID = "XYTable-GainTuning-v0"
SERVO_ID = "XYTable-Servo-v0"
GAIN_TUNING_RUNS = 5
"""Tuning runs per episode of the registered gain-tuning id."""

if GAIN_TUNING_ID not in registry:
    register(id=GAIN_TUNING_ID, entry_point="envs.gain_tuning:GainTuningEnv",
             max_episode_steps=GAIN_TUNING_RUNS)
if SERVO_ID not in registry:
    register(id=SERVO_ID, entry_point="envs.servo:ServoEnv", max_episode_steps=20_000)

__all__ += ["GAIN_TUNING_RUNS"]
