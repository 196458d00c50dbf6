"""Gymnasium environments for tuning xy-twin machines.

Importing ``envs`` registers the versioned ids, in the ``xy_twin`` namespace:

* ``xy_twin/GainTuning-v0`` (``envs.gain_tuning.GainTuningEnv``): one step is one test run
  with the gains the action sets; 5 runs per episode.
* ``xy_twin/Servo-v0`` (``envs.servo.ServoEnv``): one step is one control period; the
  action is a residual correction added to the position regulator's output.

Without importing anything first, name the module in the id, as gymnasium allows::

    env = gymnasium.make("envs:xy_twin/GainTuning-v0", randomize=True,
                         render_mode="rgb_array")

(gymnasium 1.x has no entry-point plugins, so this is how an id registers itself on
demand). The constructor keywords are documented in each class docstring. The earlier
ids ``XYTable-GainTuning-v0`` and ``XYTable-Servo-v0`` stay registered as aliases.
"""

from gymnasium.envs.registration import register, registry

__all__ = ["GAIN_TUNING_ID", "SERVO_ID"]

GAIN_TUNING_ID = "xy_twin/GainTuning-v0"
SERVO_ID = "xy_twin/Servo-v0"
GAIN_TUNING_RUNS = 5
"""Tuning runs per episode of the registered gain-tuning id."""
GAIN_TUNING_THRESHOLD = -4.0
"""The gain-tuning id's ``reward_threshold``: the analytic design's reward under the default
weights when it never saturates (``envs.gain_tuning.GainTuningEnv``, Rewards)."""

for _id, _entry, _steps, _threshold in (
        (GAIN_TUNING_ID, "envs.gain_tuning:GainTuningEnv", GAIN_TUNING_RUNS,
         GAIN_TUNING_THRESHOLD),
        ("XYTable-GainTuning-v0", "envs.gain_tuning:GainTuningEnv", GAIN_TUNING_RUNS,
         GAIN_TUNING_THRESHOLD),
        (SERVO_ID, "envs.servo:ServoEnv", 20_000, None),
        ("XYTable-Servo-v0", "envs.servo:ServoEnv", 20_000, None)):
    if _id not in registry:
        register(id=_id, entry_point=_entry, max_episode_steps=_steps,
                 reward_threshold=_threshold)

__all__ += ["GAIN_TUNING_RUNS", "GAIN_TUNING_THRESHOLD"]
