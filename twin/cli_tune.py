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
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from twin.cli_common import CONTROLLER_MODEL_HELP, err, fail
from twin.errors import ConfigError, TwinError
from twin.jsonio import json_text

__all__ = ["register"]


def tune(
    method: str | None = typer.Option(None, "--method", help="analytic, cma, optuna, ppo or "
                                      "sac (--worker: optuna)."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file (the plant the "
                                     "tuning runs are on)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    program: str = typer.Option("default", "--program", help="Tuning program: default, "
                                "compact (default shrunk to 5 %), tiny, corner, spline_line."),
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
    seed: int = typer.Option(0, "--seed"),
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
    out: Path = typer.Option(Path("runs/tune"), "--out", help="Output directory."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Tune the regulator gains, DCU coefficients and jerk limit of a machine."""
    from tuning.jobs import TuneSpec
    from tuning.jobs import tune as run_job

    if method is None and not worker:
        fail(ConfigError("method", "is required: analytic, cma, optuna, ppo or sac"))
    method = method or "optuna"
    try:
        spec = TuneSpec(method=method, machine=machine, controller_model=controller_model,
                        program=program, budget_s=budget_s,
                        out_dir=out, storage=storage, study=study, workers=workers,
                        seed=seed, max_runs=max_runs, policy=policy, train_steps=train_steps,
                        resume=resume, worker=worker, heartbeat_s=heartbeat_s,
                        grace_s=grace_s)
        training = method in ("ppo", "sac") and policy is None
        with Progress(TextColumn(f"[bold]{method}"), BarColumn(),
                      TextColumn("{task.description}"), TimeElapsedColumn(), console=err,
                      transient=True) as bar:
            task = bar.add_task("starting", total=train_steps if training else budget_s)
            start = time.perf_counter()
            state = {"runs": 0, "best": float("inf")}

            def on_trial(trial: Any) -> None:
                state["runs"] += 1
                state["best"] = min(state["best"], trial.cost)
                if not training:
                    bar.update(task, completed=min(time.perf_counter() - start, budget_s))
                bar.update(task, description=f"{state['runs']} runs, best cost "
                                             f"{state['best']:.4g}")

            def on_steps(steps: int) -> None:
                bar.update(task, completed=steps, description=f"training: {steps} runs")

            result = run_job(spec, on_trial=on_trial, progress=on_steps)
    except TwinError as exc:
        fail(exc)
    summary = result.summary()
    if as_json:
        sys.stdout.write(json_text(summary) + "\n")
        return
    from rich.table import Table

    table = Table(title=f"{method} on {machine} ({program}): {summary['runs']} runs, "
                        f"{summary['wall_time_s']:.0f} s")
    for col in ("metric", "unit", "analytic", "best", "change"):
        table.add_column(col, justify="left" if col in ("metric", "unit") else "right")
    for row in summary["comparison"]:
        change = "" if row["change_pct"] is None else f"{row['change_pct']:+.1f} %"
        table.add_row(row["metric"], row["unit"], f"{row['analytic']:.4g}",
                      f"{row['best']:.4g}", change)
    console = Console()
    console.print(table)
    for key, path in summary["files"].items():
        console.print(f"{key}: {path}", highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``twin tune`` to the ``twin`` app."""
    app.command("tune")(tune)
