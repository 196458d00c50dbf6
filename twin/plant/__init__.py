"""The plant: the machine's truth, the only package that runs MuJoCo.

``plant`` is the cross table's physics and its drives (`Plant`), ``loop`` the compiled
drive ⇄ ``mj_step`` loop between two controller periods, ``records`` the drive-rate sample
ring and the truth rows, ``model`` the MJCF a machine file builds (``python -m
twin.plant.model`` exports it for MuJoCo's viewer). The MJCF templates are data, in
``twin/models/``.
"""

from twin.plant.plant import (
    FINE_FIELDS,
    FINE_WIDTH,
    TRUTH_FIELDS,
    Plant,
    StepStatus,
    Truth,
)

__all__ = ["FINE_FIELDS", "FINE_WIDTH", "TRUTH_FIELDS", "Plant", "StepStatus",
           "Truth"]
