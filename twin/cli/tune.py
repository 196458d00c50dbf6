"""``twin tune``: automated gain tuning (analytic, CMA-ES, Optuna, PPO, SAC). The best
settings are written as ``best.toml``, which ``twin run --set-file best.toml`` accepts.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from twin.cli.common import CONTROLLER_MODEL_HELP, Builtin, choices, err, fail
from twin.errors import ConfigError, TwinError
from twin.system.jsonio import json_text

__all__ = ["register"]

Method = choices("Method", ("analytic", "cma", "optuna", "ppo", "sac"))
"""The tuning methods (``tuning.jobs.METHODS``, kept equal by a test)."""


def tune(
    method: Method | None = typer.Option(None, "--method", help="The search (--worker: "
                                         "optuna)."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file (the plant the "
                                     "tuning runs are on)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    program: Builtin = typer.Option("default", "--program", help="Tuning program (a "
                                    "built-in: compact is default shrunk to 5 %, tiny to "
                                    "1 %)."),
    budget_s: float = typer.Option(600.0, "--budget-s", help="Wall-time budget (s)."),
    storage: str | None = typer.Option(None, "--storage", envvar="TWIN_TUNE_STORAGE",
                                       help="Optuna storage URL (default "
                                       "sqlite:///OUT/optuna.db; postgresql://user:password@"
                                       "host/db lets workers on several hosts share a "
                                       "study)."),
    study: str | None = typer.Option(None, "--study", help="Optuna study name (default "
                                     "MACHINE-PROGRAM)."),
    worker: bool = typer.Option(False, "--worker", help="Join the Optuna study as a worker "
                                "(for a cluster scheduler): run its trials until the "
                                "study's run budget is spent and none is in flight, write "
                                "the study's best settings, exit 0. The first worker sets "
                                "the budget with --max-runs."),
    heartbeat_s: int = typer.Option(5, "--heartbeat-s", min=1, help="Optuna: heartbeat "
                                    "interval of a running trial (s)."),
    grace_s: int = typer.Option(20, "--grace-s", min=2, help="Optuna: a trial whose "
                                "heartbeat is older than this is taken for dead, failed "
                                "and run again (s)."),
    workers: int = typer.Option(2, "--workers", min=1, help="Worker processes (CMA, "
                                "Optuna) or parallel environments (PPO, SAC)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the search (the same seed, the "
                             "same trials)."),
    max_runs: int | None = typer.Option(None, "--max-runs", min=1,
                                        help="Stop after this many tuning runs as well."),
    policy: Path | None = typer.Option(None, "--policy", help="PPO/SAC: apply this trained "
                                       "policy instead of training. It is a pickle-based "
                                       "SB3 .zip: load only files from a trusted source."),
    train_steps: int = typer.Option(4096, "--train-steps", min=1,
                                    help="PPO/SAC: tuning runs to train for."),
    resume: bool = typer.Option(False, "--resume", help="CMA: replay OUT/cma_trials.jsonl "
                                "into the same seeded search and run only what it lacks. "
                                "PPO/SAC: continue training from "
                                "the newest checkpoint this job wrote in OUT/checkpoints "
                                "(checked against its SHA-256 manifest; any other file "
                                "there is refused, never loaded)."),
    out: Path | None = typer.Option(None, "--out", help="The job's folder; default: a new "
                                    "runs/tune/MACHINE-PROGRAM-METHOD-TIME (with --resume: "
                                    "the newest one of this machine, program and method)."),
    weight: list[str] = typer.Option([], "--weight", metavar="TERM=W", help="A cost weight "
                                     "(repeatable): max_coordinate_error, "
                                     "rms_coordinate_error, max_contour_error, "
                                     "rms_contour_error, overshoot, settling_travel, "
                                     "cycle_time, saturation_time; each term is its metric "
                                     "over the analytic design's, times W."),
    max_cycle_time_increase: str | None = typer.Option(
        None, "--max-cycle-time-increase", metavar="PCT", help="A constraint: the cycle "
        "time may grow by at most this much over the analytic design's (0% forbids any "
        "growth; 5% or 0.05)."),
    shaper: str | None = typer.Option(None, "--shaper", help="An input shaper on both axes "
                                      "(zv, mzv, zvd, ei, 2hump-ei, 3hump-ei): its frequency "
                                      "and damping are tuned too (so are a machine file's "
                                      "shapers on both axes)."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Tune the regulator gains, DCU coefficients and jerk limit of a machine (and its input
    shapers' frequency and damping)."""
    from tuning.jobs import TuneSpec
    from tuning.jobs import tune as run_job

    if method is None and not worker:
        fail(ConfigError("--method", "is required: " + ", ".join(m.value for m in Method)), as_json)
    method = "optuna" if method is None else method.value
    program = program.value
    try:
        weights = _weights(weight)
        limit = _share(max_cycle_time_increase)
        if shaper is not None:
            from twin.config.shaper_settings import shaper_overrides

            shaper_overrides(shaper, "--shaper")
        spec = TuneSpec(method=method, machine=machine, controller_model=controller_model,
                        program=program, budget_s=budget_s, weights=weights,
                        max_cycle_time_increase=limit,
                        out_dir=out, storage=storage, study=study, workers=workers,
                        seed=seed, max_runs=max_runs, policy=policy, train_steps=train_steps,
                        resume=resume, worker=worker, heartbeat_s=heartbeat_s,
                        grace_s=grace_s, shaper=shaper)
        training = method in ("ppo", "sac") and policy is None
        watch = _Watch(method, budget_s, train_steps if training else None)
        with watch:
            result = run_job(spec, on_trial=watch.on_trial, progress=watch.on_steps,
                             on_start=watch.on_start, warn=watch.warn)
            watch.runs = len(result.trials)     # the job's (an Optuna study's: every worker's)
            watch.best = result.best.cost
    except TwinError as exc:
        fail(exc, as_json)
    summary = result.summary()
    if as_json:
        sys.stdout.write(json_text(summary) + "\n")
        return
    from rich.table import Table

    from twin.analysis.report import readable

    table = Table(title=f"{method} on {machine} ({program}): {summary['runs']} runs, "
                        f"{summary['wall_time_s']:.0f} s")
    for col in ("metric", "unit", "analytic", "best", "change"):
        table.add_column(col, justify="left" if col in ("metric", "unit") else "right")
    for row in summary["comparison"]:
        change = "" if row["change_pct"] is None else f"{row['change_pct']:+.1f} %"
        table.add_row(row["metric"], row["unit"], readable(row["analytic"]),
                      readable(row["best"]), change)
    console = Console()
    console.print(table)
    changed = [r for r in summary["settings"] if r["change_pct"] != 0.0]
    if changed:
        settings = Table(title="settings that changed (best.toml)")
        for col in ("setting", "unit", "analytic", "best", "change"):
            settings.add_column(col, justify="left" if col in ("setting", "unit") else "right")
        for r in changed:
            change = "from 0" if r["change_pct"] is None or r["change_pct"] == float("inf") \
                else f"{r['change_pct']:+.1f} %"
            settings.add_row(r["setting"], r["unit"], readable(r["analytic"], 5),
                             readable(r["best"], 5), change)
        console.print(settings)
    for note in summary["notes"]:
        err.print(f"[yellow]note:[/] {escape(note)}", highlight=False, soft_wrap=True)
    for key, path in summary["files"].items():
        console.print(f"{key}: {path}", highlight=False)


def _weights(items: list[str]) -> dict[str, float]:
    """``--weight TERM=W`` options as {term: weight} (checked by ``Weights``)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise ConfigError("--weight", f"expected TERM=W (e.g. cycle_time=2), got "
                              f"{item!r}") from None
    return out


def _share(text: str | None) -> float | None:
    """``--max-cycle-time-increase``: "5%", "5 %" or "0.05" → 0.05; None for None."""
    if text is None:
        return None
    t = text.strip()
    try:
        value = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        raise ConfigError("--max-cycle-time-increase", f"expected a share such as 0%, 5% "
                          f"or 0.05, got {text!r}") from None
    return value


class _Watch:
    """What a running job shows: a progress bar on a terminal; elsewhere (a log, a cluster
    scheduler) one plain line on stderr at the first run and then every ``EVERY`` seconds,
    and the last. The job's folder and cost weights are said when it starts."""

    EVERY = 10.0

    def __init__(self, method: str, budget_s: float, train_steps: int | None):
        self.method, self.budget_s, self.train_steps = method, budget_s, train_steps
        self.tty = err.is_terminal
        self.runs, self.best, self.steps = 0, float("inf"), 0
        self.start = time.perf_counter()
        self.said = -float("inf")
        self.bar: Progress | None = None

    def __enter__(self) -> _Watch:
        if self.tty:
            self.bar = Progress(TextColumn(f"[bold]{self.method}"), BarColumn(),
                                TextColumn("{task.description}"), TimeElapsedColumn(),
                                console=err, transient=True)
            self.bar.__enter__()
            self.task = self.bar.add_task("starting", total=self.train_steps or self.budget_s)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
        elif self.runs or self.steps:
            self._line()

    def on_start(self, folder: Any, weights: dict[str, float]) -> None:
        from tuning.report import weights_text

        err.print(f"{self.method}: job folder {folder}; {weights_text(weights)} (each term "
                  "relative to the analytic design)", highlight=False, soft_wrap=True)

    def warn(self, message: str) -> None:
        err.print(f"[yellow]warning:[/] {escape(message)}", highlight=False, soft_wrap=True)

    def on_trial(self, trial: Any) -> None:
        self.runs += 1
        self.best = min(self.best, trial.cost)
        self._show()

    def on_steps(self, steps: int) -> None:
        self.steps = steps
        self._show()

    def _text(self) -> str:
        if self.train_steps is not None:
            return f"training: {self.steps} of {self.train_steps} runs"
        return f"{self.runs} runs, best cost {self.best:.4g}"

    def _show(self) -> None:
        elapsed = time.perf_counter() - self.start
        if self.bar is not None:
            done = self.steps if self.train_steps is not None else min(elapsed, self.budget_s)
            self.bar.update(self.task, completed=done, description=self._text())
        elif elapsed - self.said >= self.EVERY:
            self._line()

    def _line(self) -> None:
        elapsed = time.perf_counter() - self.start
        self.said = elapsed
        err.print(f"{self.method}: {self._text()}; {elapsed:.0f} s of {self.budget_s:g} s",
                  highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add ``twin tune`` to the ``twin`` app."""
    app.command("tune")(tune)
