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

from envs.evaluation import METRIC_UNITS, METRICS
from envs.space import TuningSettings, settings_from_dict
from tuning.evaluator import Trial
from twin.config import read_toml
from twin.controller.gains import RegulatorGains
from twin.errors import ConfigError

__all__ = ["SIGNIFICANT", "comparison", "notes", "plot_convergence", "read_overrides",
           "rounded_settings", "settings_changes", "settings_markdown", "table_markdown",
           "weights_markdown", "weights_text", "write_overrides"]

_UNITS = METRIC_UNITS

SIGNIFICANT = 5
"""Significant digits the best settings are written with (``rounded_settings``): a gain
to 0.01 % or better, finer than the DAC's step makes any difference; the jerk limit to 4."""

_SETTINGS = (("kp", "V/m"), ("ki", "V/(m·s)"), ("dcu_alpha", "V/m"), ("max_jerk", "m/s³"),
             ("shaper_frequency", "Hz"), ("shaper_damping", "1"))
"""The settings a job tunes; the shaper's only on a machine that shapes both axes."""


def _round(value: float, digits: int) -> float:
    if value == 0.0 or not math.isfinite(value):
        return float(value)
    return float(round(value, digits - 1 - math.floor(math.log10(abs(value)))))


def rounded_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """``TuningSettings.to_dict()`` values rounded to ``SIGNIFICANT`` digits (the jerk
    limit to 4): what ``best.toml`` holds, and what the job runs once more so that the
    file reproduces the figures it reports."""
    out = {"kp": [_round(v, SIGNIFICANT) for v in settings["kp"]],
           "ki": [_round(v, SIGNIFICANT) for v in settings["ki"]],
           "dcu_alpha": [[_round(v, SIGNIFICANT) for v in row]
                         for row in settings["dcu_alpha"]],
           "max_jerk": _round(settings["max_jerk"], 4)}
    for key in ("shaper_frequency", "shaper_damping"):
        if key in settings:
            out[key] = [_round(v, SIGNIFICANT) for v in settings[key]]
    return out


def settings_changes(analytic: dict[str, Any], best: dict[str, Any]) -> list[dict[str, Any]]:
    """Every setting of the best run against the analytic design's: rows ``{setting,
    unit, analytic, best, change_pct}`` (``kp x``, ``dcu_alpha y 2``, ``max_jerk``; SI)."""
    rows = []
    for name, unit in _SETTINGS:
        if name not in analytic or name not in best:
            continue
        a, b = analytic[name], best[name]
        if name == "max_jerk":
            pairs = [("max_jerk", a, b)]
        elif name == "dcu_alpha":
            pairs = [(f"α{k + 1} {ax}", va, vb) for ax, ra, rb in zip("xy", a, b, strict=True)
                     for k, (va, vb) in enumerate(zip(ra, rb, strict=True))]
        else:
            pairs = [(f"{name} {ax}", va, vb) for ax, va, vb in zip("xy", a, b, strict=True)]
        for label, va, vb in pairs:
            change = (vb - va) / abs(va) * 100.0 if va else (None if vb == va else math.inf)
            rows.append({"setting": label, "unit": unit, "analytic": va, "best": vb,
                         "change_pct": change})
    return rows


def settings_markdown(rows: list[dict[str, Any]]) -> str:
    """The settings' changes as a Markdown section (only those that changed)."""
    changed = [r for r in rows if r["change_pct"] is None or r["change_pct"] != 0.0]
    if not changed:
        return "## Settings\n\nThe analytic design's, unchanged.\n"
    out = ["## Settings that changed", "", "| setting | unit | analytic | best | change |",
           "|---|---|---:|---:|---:|"]
    for r in changed:
        change = "from 0" if r["change_pct"] in (None, math.inf) else f"{r['change_pct']:+.1f} %"
        out.append(f"| {r['setting']} | {r['unit']} | {r['analytic']:.6g} | {r['best']:.6g} "
                   f"| {change} |")
    return "\n".join(out) + "\n"


def notes(baseline: Trial, best: Trial, *, runs: int, improved: bool) -> list[str]:
    """What a reader must not miss: that nothing beat the analytic design, or the cycle
    time the best settings trade for their accuracy (more than 1 % longer)."""
    out = []
    if runs == 0:
        return ["the analytic design only (no search): best.toml holds its settings, "
                "rounded"]
    if not improved:
        out.append(f"nothing beat the analytic design in {runs} tuning runs: best.toml holds "
                   "the analytic design's own settings (rounded); running without it is "
                   "the same design")
        return out
    t0, t1 = baseline.metrics["cycle_time"], best.metrics["cycle_time"]
    if t1 > 1.01 * t0:
        j0, j1 = baseline.settings["max_jerk"], best.settings["max_jerk"]
        out.append(f"the best settings trade cycle time for accuracy: the cycle takes "
                   f"{(t1 / t0 - 1) * 100:+.1f} % ({t0:.3f} → {t1:.3f} s; max_jerk "
                   f"{j0:.4g} → {j1:.4g} m/s³); --max-cycle-time-increase 0% forbids that")
    return out


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


def write_overrides(path: Path, settings: dict[str, Any], *, header: Sequence[str] = (),
                    shaper_type: str | None = None) -> Path:
    """Write ``settings`` (``TuningSettings.to_dict()``) as an override TOML at ``path``;
    tuned shapers with their ``shaper_type`` (the machine's), so that the file turns them on
    wherever it is applied."""
    lines = [f"# {h}" for h in header]
    lines += ["", "[controller.limits]",
              f"max_jerk = {_num(settings['max_jerk'], 'm/s³')}",
              "", "[controller.regulator]",
              f"kp = {_arr(settings['kp'], 'V/m')}    # x, y",
              f"ki = {_arr(settings['ki'], 'V/(m·s)')}    # x, y",
              "# DCU alpha1..alpha3 per axis; replaces the derived dcu_order DCU",
              "dcu_alpha = [" + ", ".join(_arr(r, "V/m") for r in settings["dcu_alpha"]) + "]",
              ""]
    if "shaper_frequency" in settings:          # the machine's shapers, tuned
        for k, axis in enumerate(("x", "y")):
            lines += [f"[controller.shaper.{axis}]",
                      *([f'type = "{shaper_type}"'] if shaper_type else []),
                      f"frequency = {_num(settings['shaper_frequency'][k], 'Hz')}",
                      f"damping = {float(settings['shaper_damping'][k])!r}", ""]
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
        values: dict[str, Any] = {
            "max_jerk": _si(doc["controller"]["limits"]["max_jerk"], "m/s³", "max_jerk"),
            "kp": [_si(v, "V/m", "kp") for v in reg["kp"]],
            "ki": [_si(v, "V/(m·s)", "ki") for v in reg["ki"]],
            "dcu_alpha": [[_si(v, "V/m", "dcu_alpha") for v in r]
                          for r in reg["dcu_alpha"]]}
        shaper = doc["controller"].get("shaper")
        if shaper:
            values["shaper_frequency"] = [_si(shaper[a]["frequency"], "Hz", "frequency")
                                          for a in ("x", "y")]
            values["shaper_damping"] = [float(shaper[a]["damping"]) for a in ("x", "y")]
        return settings_from_dict(values, base)
    except (KeyError, TypeError) as exc:
        raise ConfigError(str(path), f"not a tuning override file: missing or bad {exc}") \
            from None


def comparison(baseline: Trial, best: Trial) -> list[dict[str, Any]]:
    """Rows ``{metric, unit, analytic, best, change_pct}`` (report units: µm, s): the cost,
    the cycle time beside it, then the other metrics."""
    rows = []
    for m in ("cycle_time", *(m for m in METRICS if m != "cycle_time")):
        unit, k = _UNITS[m]
        a, b = baseline.metrics[m] * k, best.metrics[m] * k
        change = (b - a) / a * 100.0 if a > 0.0 and math.isfinite(b) else None
        rows.append({"metric": m, "unit": unit, "analytic": a, "best": b,
                     "change_pct": change})
    rows.insert(0, {"metric": "cost", "unit": "1", "analytic": baseline.cost,
                    "best": best.cost,
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


def _plain_log(ax) -> None:
    """A log axis labelled with plain numbers (4.05, not 4.05×10⁰)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from twin.analysis.report import readable

    ax.set_yscale("log")
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: readable(v, 3)))
    ax.yaxis.set_minor_formatter(NullFormatter())


def plot_convergence(path: Path, trials: Sequence[Trial], baseline: Trial, *,
                     title: str, training: Sequence[float] = ()) -> Path:
    """Per tuning run, against the run number (the analytic design dashed and drawn as
    run 0, so that even a job without a search has its point): the cost with the best so
    far, the cycle time (what the accuracy may cost), the max coordinate error, and the
    settings that matter most over the analytic design's (kp per axis, α1 per axis, the
    jerk limit). With ``training`` (PPO/SAC: the cost of every training run, on
    randomised machines), a last panel shows it with a moving median. Writes a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cost = np.array([t.cost for t in trials]) if trials else np.zeros(0)
    err = np.array([t.metrics.get("max_coordinate_error", math.nan) * 1e6 for t in trials])
    cycle = np.array([t.metrics.get("cycle_time", math.nan) for t in trials])
    n = np.arange(1, len(trials) + 1)
    base_err = baseline.metrics["max_coordinate_error"] * 1e6
    base_cycle = baseline.metrics["cycle_time"]
    rows = 5 if len(training) else 4
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows), sharex=False)
    ax1, ax2, ax3, ax4 = axes[:4]
    ax1.plot([0], [baseline.cost], "o", color="C3", label="analytic design (run 0)")
    ax1.plot(n, cost, ".", color="0.6", label="run")
    if len(cost):
        ax1.plot(np.r_[0, n], np.minimum.accumulate(np.r_[baseline.cost, cost]), "-",
                 color="C0", label="best so far")
    else:
        ax1.text(0.5, 0.5, "no search: the analytic design only", transform=ax1.transAxes,
                 ha="center", va="center", color="0.4")
    ax1.axhline(baseline.cost, ls="--", color="C3")
    _plain_log(ax1)
    ax1.set_ylabel("cost (1)")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(title)
    for ax, values, base, label in ((ax2, cycle, base_cycle, "cycle time (s)"),
                                    (ax3, err, base_err, "max coordinate error (µm)")):
        ax.plot([0], [base], "o", color="C3")
        ax.plot(n, values, ".", color="0.6")
        ax.axhline(base, ls="--", color="C3")
        ax.set_ylabel(label)
        finite = values[np.isfinite(values)]
        top = max(base * 3.0, 0.0) if label.startswith("max") else \
            max(float(finite.max()) if finite.size else base, base) * 1.05
        ax.set_ylim(0.0 if label.startswith("max") else base * 0.9, top)
    a0 = baseline.settings
    for (name, pick), colour in zip((("kp x", lambda s: s["kp"][0]),
                                     ("kp y", lambda s: s["kp"][1]),
                                     ("α1 x", lambda s: s["dcu_alpha"][0][0]),
                                     ("α1 y", lambda s: s["dcu_alpha"][1][0]),
                                     ("max_jerk", lambda s: s["max_jerk"])),
                                    ("C0", "C1", "C2", "C4", "C3"), strict=True):
        base = pick(a0)
        ratio = np.array([pick(t.settings) / base for t in trials]) if base else n * np.nan
        ax4.plot(n, ratio, ".", ms=3, color=colour, label=name)
    ax4.axhline(1.0, ls="--", color="0.4")
    _plain_log(ax4)
    ax4.set_ylabel("setting ÷ analytic")
    ax4.legend(loc="upper right", fontsize=7, ncol=5)
    ax4.set_xlabel("tuning run")
    for a in (ax1, ax2, ax3, ax4):
        a.set_xlim(-0.5, max(len(trials), 1) + 0.5)
        a.grid(True, alpha=0.3)
    if len(training):
        ax5 = axes[4]
        c = np.asarray(training, dtype=float)
        k = np.arange(1, len(c) + 1)
        ax5.plot(k, c, ".", color="0.7", ms=3, label="training run")
        w = max(1, len(c) // 20)
        med = np.array([np.median(c[max(0, i - w):i + 1]) for i in range(len(c))])
        ax5.plot(k, med, "-", color="C0", label=f"moving median ({w + 1} runs)")
        ax5.axhline(baseline.cost, ls="--", color="C3", label="analytic, nominal machine")
        _plain_log(ax5)
        ax5.set_xlabel("training run (randomised machines)")
        ax5.set_ylabel("cost (1)")
        ax5.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_runs(path: Path, analytic: dict[str, np.ndarray],
              best: dict[str, np.ndarray] | None, *, title: str) -> Path:
    """The analytic design's run and the best run drawn over each other against time:
    the reference's path speed (mm/min) and each axis' coordinate error (µm), the analytic
    run dashed, the best solid (``RunOutcome.trace`` of each). ``best`` None: the analytic
    run alone (nothing beat it). Writes a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [("analytic design", analytic, "--", "C3")]
    if best is not None:
        runs.append(("best run", best, "-", "C0"))
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    for label, tr, style, colour in runs:
        t = tr["t"]
        axes[0].plot(t, tr["speed"] * 6e4, style, color=colour, lw=1.0, label=label)
        for k, ax in enumerate(axes[1:]):
            ax.plot(t, tr["error"][:, k] * 1e6, style, color=colour, lw=0.8, label=label)
    axes[0].set_ylabel("path speed (mm/min)")
    axes[1].set_ylabel("X coordinate error (µm)")
    axes[2].set_ylabel("Y coordinate error (µm)")
    axes[2].set_xlabel("time (s)")
    fig.suptitle(title + ("" if best is not None else ": nothing beat the analytic design"))
    # one legend above the panels, where it hides no trace
    fig.legend(*axes[0].get_legend_handles_labels(), loc="upper center", ncol=2,
               fontsize=8, frameon=False, bbox_to_anchor=(0.5, 0.955))
    end = max(float(tr["t"][-1]) for _, tr, _, _ in runs if len(tr["t"]))
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.set_xlim(0.0, end)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.93))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
