"""``tune(spec)``: one tuning job end to end — search, best settings, report files.

A job writes into a folder of its own: ``spec.out_dir`` when given, else
``runs/tune/<machine>-<program>-<method>-<time>`` (``job_folder``), so that two jobs, or two
machines, never mix their files, and ``--resume`` continues the newest folder of the same
machine, program and method, never another machine's checkpoints. Every method leaves the
same files there:

* ``best.toml`` — the best settings as a machine-override file (``tuning.report``);
* ``convergence.png`` — cost and max coordinate error per run against the analytic design;
* ``runs.png`` — the analytic run and the best run over each other: path speed and each
  axis' coordinate error against time;
* ``report.md`` — the table best vs analytic;
* ``result.json`` — the summary (also what ``twin tune --json`` prints) with every trial
  and the cost weights the job used.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from envs.evaluation import Weights
from envs.programs import PROGRAMS
from tuning.cma_job import run_cma
from tuning.evaluator import Evaluator, Trial
from tuning.report import (
    comparison,
    notes,
    plot_convergence,
    plot_runs,
    rounded_settings,
    settings_changes,
    settings_markdown,
    table_markdown,
    weights_markdown,
    write_overrides,
)
from twin.config import MachineConfig, load_machine
from twin.config.shaper_settings import shaper_overrides
from twin.errors import ConfigError
from twin.system.jsonio import folder_lock, output_dir, write_json_atomic, write_text_atomic

__all__ = ["JOBS_ROOT", "METHODS", "TuneResult", "TuneSpec", "job_folder", "tune"]

METHODS = ("analytic", "cma", "optuna", "ppo", "sac")

JOBS_ROOT = Path("runs/tune")
"""Where jobs without an ``out_dir`` get their folders."""


@dataclass(frozen=True)
class TuneSpec:
    """What a tuning job does.

    Attributes
    ----------
    method : str
        One of ``METHODS``.
    machine : str
        Preset name or TOML path: the machine the tuning runs are on.
    controller_model : str or None
        Preset name or TOML path of the machine as the controller believes it to be (the
        analytic design and the tuning space's scales come from it); None: the machine.
    program : str
        Tuning program (``envs.programs.PROGRAMS``).
    budget_s : float
        Wall-time budget of the search or training (s).
    out_dir : Path or None
        Where the files go; None: a new folder under ``JOBS_ROOT`` (``job_folder``), or with
        ``resume`` the newest one of the same machine, program and method.
    storage : str or None
        Optuna storage URL; None: ``sqlite:///<out_dir>/optuna.db``.
    study : str or None
        Optuna study name; None: ``<machine>-<program>``.
    workers : int
        Worker processes (CMA/Optuna) or parallel environments (PPO/SAC).
    seed : int
    max_runs : int or None
        Stop after this many tuning runs as well (CMA/Optuna).
    policy : Path or None
        PPO/SAC: apply this trained policy (trusted file) instead of training.
    train_steps : int
        PPO/SAC: tuning runs to train for.
    policy_runs : int
        Tuning runs a policy gets on the target machine.
    resume : bool
        PPO/SAC: continue training from the newest checkpoint this job wrote in
        ``out_dir/checkpoints`` (checked against its SHA-256 manifest); otherwise training
        starts afresh and loads nothing it finds there. CMA: replay the trial log
        ``out_dir/cma_trials.jsonl`` into the same seeded search and run only what it
        lacks; otherwise the log starts afresh.
    weights : dict
        Cost weights by metric (``envs.evaluation.Weights``).
    max_cycle_time_increase : float or None
        A constraint: the cycle time may grow by at most this share (1; 0.0 forbids any
        growth) of the analytic design's (``envs.gain_tuning.Tuning``); None: none.
    worker : bool
        Optuna: join the study as one of its workers (``optuna_job.run_worker``): run its
        trials until the study's run budget (set by the first worker's ``max_runs``) is
        spent and nothing is left in flight, then write the study's best settings.
    heartbeat_s, grace_s : int
        Optuna: heartbeat interval of a running trial, and the age of the last heartbeat
        after which its worker is taken for dead (s).
    shaper : str or None
        An input shaper on both axes (``twin.config.shaper_settings.SHAPER_TYPES``): its
        frequency and damping are tuned with the gains (``envs.space``); None: the
        machine's shapers (tuned when it shapes both axes).
    """

    method: str
    machine: str = "tomsk_xy"
    controller_model: str | None = None
    program: str = "default"
    budget_s: float = 600.0
    out_dir: Path | None = None
    storage: str | None = None
    study: str | None = None
    workers: int = 2
    seed: int = 0
    max_runs: int | None = None
    policy: Path | None = None
    train_steps: int = 4096
    policy_runs: int = 5
    resume: bool = False
    weights: dict[str, float] = field(default_factory=dict)
    max_cycle_time_increase: float | None = None
    worker: bool = False
    heartbeat_s: int = 5
    grace_s: int = 20
    shaper: str | None = None

    def __post_init__(self) -> None:
        if self.shaper is not None:
            shaper_overrides(self.shaper, "shaper")
        if self.method not in METHODS:
            raise ConfigError("method", f"must be one of {', '.join(METHODS)}, got "
                              f"{self.method!r}")
        if self.program not in PROGRAMS:
            raise ConfigError("program", f"unknown tuning program {self.program!r}; valid: "
                              f"{', '.join(PROGRAMS)}")
        if not (math.isfinite(self.budget_s) and self.budget_s > 0):
            raise ConfigError("budget_s", f"must be a finite number > 0 (s), got "
                              f"{self.budget_s!r}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) \
                or self.workers < 1:
            raise ConfigError("workers", f"must be an integer >= 1, got {self.workers!r}")
        Weights.from_mapping(self.weights)
        limit = self.max_cycle_time_increase
        if limit is not None and not (isinstance(limit, int | float) and math.isfinite(limit)
                                      and limit >= 0.0):
            raise ConfigError("max_cycle_time_increase", f"must be a share >= 0 (0.05 is "
                              f"5 %), got {limit!r}")
        if self.worker and self.method != "optuna":
            raise ConfigError("worker", f"workers join Optuna studies; --method is "
                              f"{self.method!r}")
        for name in ("heartbeat_s", "grace_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(name, f"must be an integer >= 1 (s), got {value!r}")
        if self.grace_s <= self.heartbeat_s:
            raise ConfigError("grace_s", f"must exceed heartbeat_s ({self.heartbeat_s} s), "
                              f"got {self.grace_s}")
        if self.policy is not None and not Path(self.policy).is_file():
            raise ConfigError("policy", f"no such file: {self.policy}")

    def machine_name(self) -> str:
        """The machine as a folder name: a preset's name, a TOML file's stem."""
        return Path(self.machine).stem if self.machine.endswith(".toml") else self.machine

    def study_name(self, cfg: MachineConfig) -> str:
        """The Optuna study: ``study``, or ``<machine>-<program>``."""
        return self.study or f"{cfg.name}-{self.program}"


@dataclass
class TuneResult:
    """What a job found.

    Attributes
    ----------
    spec : TuneSpec
    baseline, best : Trial
        The analytic design and the best settings as written to ``best.toml``: the best
        trial's (cost-wise; the baseline's if nothing beat it) rounded
        (``tuning.report.rounded_settings``) and run once more, so that the file
        reproduces the figures reported.
    trials : list of Trial
        Every run of the job, in order (for Optuna: the whole study's).
    files : dict of str to Path
        ``overrides``, ``plot``, ``report``, ``result`` (and ``policy`` after training).
    wall_time : float
        Duration of the job (s).
    """

    spec: TuneSpec
    baseline: Trial
    best: Trial
    trials: list[Trial]
    files: dict[str, Path]
    wall_time: float
    weights: dict[str, float] = field(default_factory=dict)
    """The cost weights of the job (``envs.evaluation.Weights``, every metric's)."""
    improved: bool = False
    """A search beat the analytic design (with the settings as written). When none did,
    ``best`` is the analytic design rounded: its figures differ from ``baseline``'s by
    the rounding only."""

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (µm, s in the comparison; SI in the trials and settings)."""
        return {
            "method": self.spec.method, "machine": self.spec.machine,
            "program": self.spec.program, "runs": len(self.trials),
            "wall_time_s": self.wall_time,
            "baseline": self.baseline.to_dict(), "best": self.best.to_dict(),
            "improved": self.improved,
            "notes": notes(self.baseline, self.best, runs=len(self.trials),
                           improved=self.improved),
            "comparison": comparison(self.baseline, self.best),
            "settings": settings_changes(self.baseline.settings, self.best.settings),
            "max_coordinate_error_reduction_pct": 100.0 * (
                1.0 - self.best.metrics["max_coordinate_error"]
                / self.baseline.metrics["max_coordinate_error"]),
            "files": {k: str(v) for k, v in self.files.items()},
            "weights": dict(self.weights),
            "spec": {k: (str(v) if isinstance(v, Path) else v)
                     for k, v in dataclasses.asdict(self.spec).items()},
        }


def job_folder(spec: TuneSpec, root: Path = JOBS_ROOT) -> Path:
    """The folder of a job without an ``out_dir``: a new
    ``<root>/<machine>-<program>-<method>-<YYYYmmdd-HHMMSS>``, or with ``resume`` the newest
    existing one of that machine, program and method.

    Raises
    ------
    ConfigError
        ``resume`` with no earlier job of that machine, program and method.
    """
    stem = f"{spec.machine_name()}-{spec.program}-{spec.method}"
    if spec.resume:
        earlier = sorted(p for p in root.glob(f"{stem}-*") if p.is_dir())
        if not earlier:
            raise ConfigError("resume", f"no earlier {spec.method} job of {spec.machine_name()} "
                              f"on {spec.program} in {root} (give its folder with --out)")
        return earlier[-1]
    return root / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"


FINISH_S = 2.0
"""Seconds of a job's budget kept for its files (best settings, JSON, report, plot)."""


def _search(spec: TuneSpec, ev: Evaluator, files: dict[str, Path],
            progress: Callable[[int], None] | None, budget_s: float,
            training: list[float], warn: Callable[[str], None] | None = None) -> list[Trial]:
    """Run the method within ``budget_s`` (what is left of the job's budget once the
    machine is loaded and the baseline has run); returns its trials. PPO/SAC append the
    cost of every training run to ``training``."""
    if spec.method == "analytic" or budget_s <= 0.0:
        return []
    if spec.method == "cma":
        run_cma(ev, budget_s=budget_s, max_evals=spec.max_runs, seed=spec.seed,
                log=spec.out_dir / "cma_trials.jsonl", resume=spec.resume, warn=warn)
        files["log"] = spec.out_dir / "cma_trials.jsonl"
        return ev.trials
    if spec.method == "optuna":
        from tuning.optuna_job import run_optuna, run_worker
        from tuning.study_storage import default_storage

        job = run_worker if spec.worker else run_optuna
        return job(ev, storage=spec.storage or default_storage(spec.out_dir),
                   study_name=spec.study_name(ev.tuning.cfg), budget_s=budget_s,
                   max_trials=spec.max_runs, seed=spec.seed, heartbeat_s=spec.heartbeat_s,
                   grace_s=spec.grace_s)
    from tuning.sb3_job import apply_policy, train

    policy = spec.policy
    if policy is None:
        # the policy's runs on the machine come after the training, inside the budget
        applying = spec.policy_runs * ev.baseline.wall_time + 1.0   # + loading the policy
        policy = train(spec.method, machine=ev.tuning.cfg, program=spec.program,
                       out_dir=spec.out_dir / "checkpoints", total_steps=spec.train_steps,
                       budget_s=max(budget_s - applying, 1e-3), n_envs=spec.workers,
                       seed=spec.seed, weights=ev.tuning.weights, progress=progress,
                       resume=spec.resume, on_cost=training.append,
                       tensorboard=spec.out_dir / "tensorboard")
        files["policy"] = policy
        files["tensorboard"] = spec.out_dir / "tensorboard"
    trials, _ = apply_policy(policy, ev.tuning.cfg, program=spec.program,
                             runs=spec.policy_runs, weights=ev.tuning.weights,
                             on_trial=ev.on_trial)
    return trials


def tune(spec: TuneSpec, *, on_trial: Callable[[Trial], None] | None = None,
         progress: Callable[[int], None] | None = None,
         on_start: Callable[[Path, dict[str, float]], None] | None = None,
         warn: Callable[[str], None] | None = None) -> TuneResult:
    """Run the job ``spec``; write the override TOML, plot, table and JSON.

    Parameters
    ----------
    spec : TuneSpec
    on_trial : callable(Trial), optional
        Called after every tuning run of this process.
    progress : callable(int), optional
        PPO/SAC: called with the number of training steps done.
    on_start : callable(Path, dict), optional
        Called once the job has its folder, with the folder and the cost weights.
    warn : callable(str), optional
        Told what the job skips (CMA: lines of a resumed trial log that hold no trial).
    """
    start = time.perf_counter()
    if spec.out_dir is None:
        spec = dataclasses.replace(spec, out_dir=job_folder(spec))
    cfg: MachineConfig = load_machine(spec.machine)
    if spec.shaper is not None:
        cfg = cfg.with_overrides(shaper_overrides(spec.shaper, "shaper"))
    if spec.method == "optuna" and spec.storage:   # a shared study: checked before writing
        from tuning.study_storage import check_study, study_identity

        belief = None if spec.controller_model is None else load_machine(spec.controller_model)
        check_study(spec.storage, spec.study_name(cfg), study_identity(
            cfg, belief, spec.program, Weights.from_mapping(spec.weights)))
    out = output_dir(spec.out_dir)
    with folder_lock(out):
        if on_start is not None:
            on_start(out, dataclasses.asdict(Weights.from_mapping(spec.weights)))
        return _tune_in(spec, cfg, out, start, on_trial, progress, warn)


def _tune_in(spec: TuneSpec, cfg: MachineConfig, out: Path, start: float,
             on_trial: Callable[[Trial], None] | None,
             progress: Callable[[int], None] | None,
             warn: Callable[[str], None] | None = None) -> TuneResult:
    """The job, in its locked folder ``out``."""
    files: dict[str, Path] = {}
    with Evaluator.create(cfg, spec.program, weights=Weights.from_mapping(spec.weights),
                          workers=spec.workers if spec.method in ("cma", "optuna") else 1,
                          on_trial=on_trial, belief=spec.controller_model,
                          max_cycle_time_increase=spec.max_cycle_time_increase) as ev:
        # what is left, less the time kept for the files (and the one run of the best
        # settings as written, which follows the search)
        left = spec.budget_s - (time.perf_counter() - start) - FINISH_S
        training: list[float] = []
        trials = _search(spec, ev, files, progress, left, training, warn)
        baseline = ev.baseline
        found = min([baseline, *trials], key=lambda t: t.cost)
        best = ev.settings_trial(rounded_settings(found.settings), found.x)
        improved = found is not baseline and best.cost < baseline.cost * (1.0 - 1e-9)
        if found is not baseline and not improved:
            # rounding lost the little it had won: the analytic design stands, as written
            best = ev.settings_trial(rounded_settings(baseline.settings), baseline.x)
        traces = (ev.trace(baseline.settings),
                  ev.trace(best.settings) if improved else None)
    said = notes(baseline, best, runs=len(trials), improved=improved)
    header = (f"twin tune --method {spec.method}: best settings for {cfg.name}, program "
              f"{spec.program}", f"cost {best.cost:.4g} (analytic {baseline.cost:.4g}); "
              f"max coordinate error {best.metrics['max_coordinate_error'] * 1e6:.3g} µm "
              f"(analytic {baseline.metrics['max_coordinate_error'] * 1e6:.3g} µm); cycle "
              f"time {best.metrics['cycle_time']:.3f} s (analytic "
              f"{baseline.metrics['cycle_time']:.3f} s)", *said,
              "apply with: twin run --set-file THIS_FILE")
    # what the job is for comes first: the settings and the result; the figure and the
    # report after them, so that a failing plot (a full disk, a broken backend) loses
    # neither
    files["overrides"] = write_overrides(out / "best.toml", best.settings, header=header,
                                         shaper_type=cfg.controller.shaper.x.type)
    files["result"] = out / "result.json"
    files["report"] = out / "report.md"
    files["plot"] = out / "convergence.png"
    if traces[0] is not None:             # the analytic run finished (it always does)
        files["runs"] = out / "runs.png"
    weights = dataclasses.asdict(ev.tuning.weights)     # the weights the runs were costed with
    result = TuneResult(spec, baseline, best, list(trials), files,
                        time.perf_counter() - start, weights, improved)
    doc = {**result.summary(), "trials": [t.to_dict() for t in trials],
           "training_costs": training}
    write_json_atomic(files["result"], doc, indent=1)
    rows = comparison(baseline, best)
    limit = ("" if spec.max_cycle_time_increase is None else
             f"Constraint: the cycle time grows by at most "
             f"{spec.max_cycle_time_increase * 100:g} % over the analytic design's.\n\n")
    write_text_atomic(files["report"],
                      f"# {spec.method} tuning of {cfg.name} ({spec.program})\n\n"
                      f"{len(trials)} tuning runs, {result.wall_time:.0f} s.\n\n"
                      + "".join(f"**{n[0].upper()}{n[1:]}.**\n\n" for n in said)
                      + table_markdown(rows) + "\n"
                      + settings_markdown(settings_changes(baseline.settings, best.settings))
                      + "\n" + weights_markdown(weights) + "\n" + limit
                      + "Figures: `convergence.png` (every tuning run against the analytic "
                      "design), `runs.png` (the analytic run and the best run over each "
                      "other: path speed and coordinate errors against time).\n")
    title = f"{spec.method} on {cfg.name} ({spec.program})"
    plot_convergence(files["plot"], trials, baseline, title=title, training=training)
    if "runs" in files and traces[0] is not None:
        plot_runs(files["runs"], traces[0], traces[1], title=title)
    return result
