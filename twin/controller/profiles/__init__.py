"""Acceleration laws: 1-D moves along the path from any start speed to any end speed.

Five laws, chosen by name at run time (`LAWS`): the classic ``trapezoid`` (constant
acceleration), seed 000's ``parabolic`` acceleration, ``cosine``, ``cubic`` (jerk a cubic in
time, so acceleration and jerk are both continuous) and the seven-phase ``jerk-limited``
S-curve computed by ruckig. `twin.controller.profiles.laws` defines each one exactly.

Typical use::

    >>> import numpy as np
    >>> limits = Limits(max_velocity=0.015, max_acceleration=0.2, max_jerk=5.0)
    >>> move = plan_move("parabolic", 0.01, v_start=0.0, v_end=0.0, v_max=0.015,
    ...                  limits=limits)
    >>> round(move.duration, 4)                 # s
    0.8008
    >>> s, v, a, j = move.at(0.1)               # one controller tick: m, m/s, m/s², m/s³
    >>> s, v, a, j = move.sample(np.linspace(0.0, move.duration, 1000))
    >>> float(s[-1]), float(v.max())            # the whole 10 mm, cruising at v_max
    (0.01, 0.015)

The look-ahead planner uses the closed forms `max_end_speed` and `min_distance` per block.
"""

from twin.controller.profiles.laws import LAWS, SHAPES, Shape, max_end_speed, min_distance
from twin.controller.profiles.limits import Limits
from twin.controller.profiles.plan import plan_move
from twin.controller.profiles.profile import Blend, Polynomial, Profile, Segment

__all__ = [
    "LAWS",
    "SHAPES",
    "Blend",
    "Limits",
    "Polynomial",
    "Profile",
    "Segment",
    "Shape",
    "max_end_speed",
    "min_distance",
    "plan_move",
]
