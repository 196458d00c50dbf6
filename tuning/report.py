"""What a tuning job leaves behind: the override TOML, the convergence plot, the table.

``write_overrides`` writes the best settings as a machine-override file in the layout of a
machine TOML (``[controller.limits]``, ``[controller.regulator]``), per-axis values as
``[x, y]`` arrays and the DCU coefficients as ``dcu_alpha = [[α1, α2, α3], [...]]`` (V/m)::

    twin run --set-file runs/tune/best.toml

``read_overrides`` reads such a file back into ``TuningSettings`` (and is what the tests use
to check the file reproduces the tuned run).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from envs.evaluation import METRICS
from envs.space import TuningSettings
from tuning.evaluator import Trial
from twin.config import read_toml
from twin.controller.regulator import RegulatorGains
from twin.errors import ConfigError

__all__ = ["comparison", "plot_convergence", "read_overrides", "table_markdown",
           "write_overrides"]

_UNITS = {m: ("s", 1.0) if "time" in m else ("µm", 1e6) for m in METRICS}


def _num(v: float) -> str:
    return repr(float(v))


def _arr(values: Sequence[float]) -> str:
    return "[" + ", ".join(_num(v) for v in values) + "]"


def write_overrides(path: Path, settings: dict[str, Any], *, header: Sequence[str] = ()
                    ) -> Path:
    """Write ``settings`` (``TuningSettings.to_dict()``) as an override TOML at ``path``."""
    lines = [f"# {h}" for h in header]
    lines += ["", "[controller.limits]",
              f"max_jerk = {_num(settings['max_jerk'])}            # m/s³",
              "", "[controller.regulator]",
              f"kp = {_arr(settings['kp'])}    # x, y (V/m)",
              f"ki = {_arr(settings['ki'])}    # x, y (V/(m·s))",
              "# DCU alpha1..alpha3 per axis (V/m); replaces the derived dcu_order DCU",
              "dcu_alpha = [" + ", ".join(_arr(r) for r in settings["dcu_alpha"]) + "]", ""]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    tmp.replace(path)
    return path


def read_overrides(path: Path, base: RegulatorGains) -> TuningSettings:
    """Settings of an override file written by ``write_overrides``; ``base`` supplies the
    DAC, output and trip limits.

    Raises
    ------
    ConfigError
        A missing key or a malformed value (naming it).
    """
    doc = read_toml(path)
    try:
        reg = doc["controller"]["regulator"]
        jerk = doc["controller"]["limits"]["max_jerk"]
        gains = RegulatorGains(kp=tuple(reg["kp"]), ki=tuple(reg["ki"]),
                               dcu_alpha=tuple(tuple(r) for r in reg["dcu_alpha"]),
                               output_limit=base.output_limit, dac_bits=base.dac_bits,
                               following_error_limit=base.following_error_limit)
    except (KeyError, TypeError) as exc:
        raise ConfigError(str(path), f"not a tuning override file: missing or bad {exc}") \
            from None
    return TuningSettings(gains, float(jerk))


def comparison(baseline: Trial, best: Trial) -> list[dict[str, Any]]:
    """Rows ``{metric, unit, analytic, best, change_pct}`` (report units: µm, s)."""
    rows = []
    for m in METRICS:
        unit, k = _UNITS[m]
        a, b = baseline.metrics[m] * k, best.metrics[m] * k
        change = (b - a) / a * 100.0 if a > 0.0 and math.isfinite(b) else None
        rows.append({"metric": m, "unit": unit, "analytic": a, "best": b,
                     "change_pct": change})
    rows.append({"metric": "cost", "unit": "1", "analytic": baseline.cost, "best": best.cost,
                 "change_pct": (best.cost - baseline.cost) / baseline.cost * 100.0})
    return rows


def table_markdown(rows: list[dict[str, Any]]) -> str:
    """The comparison as a Markdown table."""
    out = ["| metric | unit | analytic | best | change |", "|---|---|---:|---:|---:|"]
    for r in rows:
        change = "" if r["change_pct"] is None else f"{r['change_pct']:+.1f} %"
        out.append(f"| {r['metric']} | {r['unit']} | {r['analytic']:.4g} | {r['best']:.4g} "
                   f"| {change} |")
    return "\n".join(out) + "\n"


def plot_convergence(path: Path, trials: Sequence[Trial], baseline: Trial, *,
                     title: str) -> Path:
    """Cost per run with the best so far, and the max coordinate error, against the run
    number; the analytic baseline dashed. Writes a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cost = np.array([t.cost for t in trials]) if trials else np.zeros(0)
    err = np.array([t.metrics.get("max_coordinate_error", math.nan) * 1e6 for t in trials])
    n = np.arange(1, len(trials) + 1)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax1.plot(n, cost, ".", color="0.6", label="run")
    if len(cost):
        ax1.plot(n, np.minimum.accumulate(np.minimum(cost, baseline.cost)), "-", color="C0",
                 label="best so far")
    ax1.axhline(baseline.cost, ls="--", color="C3", label="analytic")
    ax1.set_yscale("log")
    ax1.set_ylabel("cost (1)")
    ax1.legend(loc="upper right")
    ax1.set_title(title)
    ax2.plot(n, err, ".", color="0.6")
    ax2.axhline(baseline.metrics["max_coordinate_error"] * 1e6, ls="--", color="C3")
    ax2.set_ylabel("max coordinate error (µm)")
    ax2.set_xlabel("tuning run")
    top = baseline.metrics["max_coordinate_error"] * 1e6 * 3.0
    ax2.set_ylim(0.0, top)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
