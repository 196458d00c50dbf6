"""What a tuning job leaves behind: the override TOML, the convergence plot, the table.

``write_overrides`` writes the best settings as a machine-override file in the layout of a
machine TOML (``[controller.limits]``, ``[controller.regulator]``), every value with its
unit (``kp = ["2150.3 V/m", "1980.7 V/m"]``, ``max_jerk = "4.2 m/s³"``; the unit is part of
the value, so nobody has to guess the file's units), per-axis values as ``[x, y]`` arrays and
the DCU coefficients as ``dcu_alpha = [[α1, α2, α3], [...]]``::

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
from twin.controller.gains import RegulatorGains
from twin.errors import ConfigError

__all__ = ["comparison", "plot_convergence", "read_overrides", "table_markdown",
           "weights_markdown", "weights_text", "write_overrides"]

_UNITS = {m: ("s", 1.0) if "time" in m else ("µm", 1e6) for m in METRICS}


def _num(v: float, unit: str) -> str:
    """A TOML string holding ``v`` (exact: ``repr``) with its unit."""
    return f'"{float(v)!r} {unit}"'


def _arr(values: Sequence[float], unit: str) -> str:
    return "[" + ", ".join(_num(v, unit) for v in values) + "]"


def _si(value: Any, unit: str, where: str) -> float:
    """A value of an override file in SI: a number as it is, a quantity converted."""
    from twin.config.quantities import to_si

    return to_si(value, unit, where) if isinstance(value, str) else float(value)


def weights_text(weights: dict[str, float]) -> str:
    """The cost weights in one line: ``cost = 1·max_coordinate_error + 0.5·...`` (each term
    is its metric over the analytic design's, times the weight)."""
    return "cost = " + " + ".join(f"{w:g}·{name}" for name, w in weights.items() if w)


def weights_markdown(weights: dict[str, float]) -> str:
    """The cost weights as a Markdown section of the report."""
    rows = "\n".join(f"| {name} | {w:g} |" for name, w in weights.items())
    return ("## Cost weights\n\nEach term is the run's metric relative to the analytic "
            "design's, times its weight.\n\n| term | weight |\n| --- | --- |\n" + rows + "\n")


def write_overrides(path: Path, settings: dict[str, Any], *, header: Sequence[str] = ()
                    ) -> Path:
    """Write ``settings`` (``TuningSettings.to_dict()``) as an override TOML at ``path``."""
    lines = [f"# {h}" for h in header]
    lines += ["", "[controller.limits]",
              f"max_jerk = {_num(settings['max_jerk'], 'm/s³')}",
              "", "[controller.regulator]",
              f"kp = {_arr(settings['kp'], 'V/m')}    # x, y",
              f"ki = {_arr(settings['ki'], 'V/(m·s)')}    # x, y",
              "# DCU alpha1..alpha3 per axis; replaces the derived dcu_order DCU",
              "dcu_alpha = [" + ", ".join(_arr(r, "V/m") for r in settings["dcu_alpha"]) + "]",
              ""]
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
        jerk = _si(doc["controller"]["limits"]["max_jerk"], "m/s³", "max_jerk")
        gains = RegulatorGains(kp=tuple(_si(v, "V/m", "kp") for v in reg["kp"]),
                               ki=tuple(_si(v, "V/(m·s)", "ki") for v in reg["ki"]),
                               dcu_alpha=tuple(tuple(_si(v, "V/m", "dcu_alpha") for v in r)
                                               for r in reg["dcu_alpha"]),
                               output_limit=base.output_limit, dac_bits=base.dac_bits,
                               following_error_limit=base.following_error_limit)
    except (KeyError, TypeError) as exc:
        raise ConfigError(str(path), f"not a tuning override file: missing or bad {exc}") \
            from None
    return TuningSettings(gains, jerk)


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
                     title: str, training: Sequence[float] = ()) -> Path:
    """Cost per run with the best so far, and the max coordinate error, against the run
    number; the analytic baseline dashed and drawn as run 0, so that even a job without
    a search (``analytic``) has its point. With ``training`` (PPO/SAC: the cost of every
    training run, on randomised machines), a third panel shows it with a moving median.
    Writes a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cost = np.array([t.cost for t in trials]) if trials else np.zeros(0)
    err = np.array([t.metrics.get("max_coordinate_error", math.nan) * 1e6 for t in trials])
    n = np.arange(1, len(trials) + 1)
    base_err = baseline.metrics["max_coordinate_error"] * 1e6
    rows = 3 if len(training) else 2
    fig, axes = plt.subplots(rows, 1, figsize=(8, 3 * rows))
    ax1, ax2 = axes[0], axes[1]
    ax1.plot([0], [baseline.cost], "o", color="C3", label="analytic design (run 0)")
    ax1.plot(n, cost, ".", color="0.6", label="run")
    if len(cost):
        ax1.plot(np.r_[0, n], np.minimum.accumulate(np.r_[baseline.cost, cost]), "-",
                 color="C0", label="best so far")
    else:
        ax1.text(0.5, 0.5, "no search: the analytic design only", transform=ax1.transAxes,
                 ha="center", va="center", color="0.4")
    ax1.axhline(baseline.cost, ls="--", color="C3")
    ax1.set_yscale("log")
    ax1.set_ylabel("cost (1)")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(title)
    ax2.plot([0], [base_err], "o", color="C3")
    ax2.plot(n, err, ".", color="0.6")
    ax2.axhline(base_err, ls="--", color="C3")
    ax2.set_ylabel("max coordinate error (µm)")
    ax2.set_xlabel("tuning run")
    ax2.set_ylim(0.0, base_err * 3.0)
    for a in (ax1, ax2):
        a.set_xlim(-0.5, max(len(trials), 1) + 0.5)
    if len(training):
        ax3 = axes[2]
        c = np.asarray(training, dtype=float)
        k = np.arange(1, len(c) + 1)
        ax3.plot(k, c, ".", color="0.7", ms=3, label="training run")
        w = max(1, len(c) // 20)
        med = np.array([np.median(c[max(0, i - w):i + 1]) for i in range(len(c))])
        ax3.plot(k, med, "-", color="C0", label=f"moving median ({w + 1} runs)")
        ax3.axhline(baseline.cost, ls="--", color="C3", label="analytic, nominal machine")
        ax3.set_yscale("log")
        ax3.set_xlabel("training run (randomised machines)")
        ax3.set_ylabel("cost (1)")
        ax3.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
