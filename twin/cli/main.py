"""The ``twin`` command: run programs on the twin, experiments, manual mode, recordings.

Every command prints human output on stderr (tables, progress) and, with ``--json``,
exactly one JSON object on stdout. Bad input exits with code 2 and a message that names
the place (G-code line and column, config field).
"""

from __future__ import annotations

from twin.system import interrupts

# A Ctrl-C while the command is still importing (numpy, MuJoCo, ...) ends it quietly with the
# shell's 130 instead of a KeyboardInterrupt traceback, even where an import drops the
# exception (twin.system.interrupts); a run installs its own handlers (twin.session.run_end).
interrupts.install()

import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.markup import escape  # noqa: E402
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn  # noqa: E402
from rich.table import Table  # noqa: E402

from twin.cli.common import (  # noqa: E402
    CONTROLLER_MODEL_HELP,
    RERUN_HELP,
    RUN_ROWS,
    Builtin,
    PlannerMode,
    err,
    fail,
    print_paths,
    report_dry_run,
    rerun_target,
    summary_table,
)
from twin.config import available_machines, diff_machines, field_unit, load_machine  # noqa: E402
from twin.config.overrides import SET_HELP  # noqa: E402
from twin.errors import ConfigError, TwinError  # noqa: E402
from twin.system.jsonio import forget_outputs, json_text  # noqa: E402

__all__ = ["app"]

app = typer.Typer(help="xy-twin: a digital twin of a two-axis CNC cross table.",
                  no_args_is_help=True, add_completion=False)

MachineOpt = typer.Option("tomsk_xy", "--machine", "-m",
                          help="Machine preset name or TOML file (the plant).")
ModelOpt = typer.Option(None, "--controller-model", help=CONTROLLER_MODEL_HELP)
OutOpt = typer.Option(Path("runs"), "--out", help="Directory for run records.")
JsonOpt = typer.Option(False, "--json", help="Print exactly one JSON object on stdout.")


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            sys.stdout.write(f"xy-twin {version('xy-twin')}\n")
        except PackageNotFoundError:   # run from a source tree that was never installed
            sys.stdout.write("xy-twin (not installed)\n")
        raise typer.Exit()


@app.callback()
def main(show_version: bool = typer.Option(False, "--version", callback=_version,
                                           is_eager=True, help="Print the version and exit.")
         ) -> None:
    """xy-twin: a digital twin of a two-axis CNC cross table."""
    forget_outputs()        # a command answers only for the folders it makes itself


def _emit(obj: dict[str, Any], as_json: bool) -> None:
    if as_json:
        sys.stdout.write(json_text(obj) + "\n")


def _progress() -> Progress:
    """A run's progress on a terminal; elsewhere nothing (not even the blank line a
    stopped live display leaves before an error)."""
    return Progress(TextColumn("[bold]sim"), BarColumn(), TextColumn("{task.description}"),
                    TimeElapsedColumn(), console=err, transient=True,
                    disable=not err.is_terminal)


# --------------------------------------------------------------------------- run
def _summary_table(summary: dict[str, Any], title: str) -> Table:
    return summary_table({"value": summary}, RUN_ROWS, title=title, skip_missing=True)


def _run(program: Path | None, machine: str, profile: str | None, planner: str | None,
         dcu_order: int | None, period: float | None, sets: list[str], rerun: str,
         out: Path, as_json: bool, dry_run: bool = False, builtin: str = "default",
         driver: str = "sim", rt_priority: int = 0, set_file: Path | None = None,
         controller_model: str | None = None, rerun_port: int = 9876) -> None:
    from twin.config.overrides import parse_sets, set_file_overrides
    from twin.config.shaper_settings import split_profile
    from twin.session.run import RunSpec, run
    from twin.session.run_end import RunInterrupted

    try:
        if profile is not None:
            split_profile(profile, "--profile")
        spec = RunSpec(machine=machine, controller_model=controller_model,
                       program=str(program) if program else None,
                       builtin=builtin, profile=profile, planner=planner,
                       dcu_order=dcu_order, period=period, overrides={
                           **(set_file_overrides(set_file) if set_file else {}),
                           **parse_sets(sets)},
                       driver=driver, rt_priority=rt_priority)
        if dry_run:
            from twin.session.dry_run import dry_run as plan_only

            if driver != "sim":
                raise ConfigError("--dry-run", "plans on the machine file; it drives no "
                                  f"I/O (drop --driver {driver})")
            planned = plan_only(spec, out_dir=out, rerun=rerun)
            report_dry_run(planned, out, as_json)
            if planned["status"] != "FINISHED":
                raise typer.Exit(1)
            return
        with _progress() as bar:
            task = bar.add_task("starting", total=None)

            def progress(t: float, done: float) -> None:
                share = "" if done != done else f", {done:.0%} of the program"
                bar.update(task, description=f"{t:.1f} s simulated{share}")

            def warn(message: str) -> None:
                bar.console.print(f"[yellow]warning:[/] {message}", highlight=False,
                                  soft_wrap=True)

            # the record goes to the file as it grows: memory does not grow with the run
            result = run(spec, out_dir=out, rerun=rerun, progress=progress, warn=warn,
                         keep_record=False, rerun_port=rerun_port)
    except RunInterrupted as exc:   # the record was complete: report it, then stop
        _report(exc.result.summary, out, as_json)
        raise typer.Exit(128 + exc.signum) from None
    except TwinError as exc:
        fail(exc, as_json)
    summary = result.summary
    for note in summary.get("input_warnings", ()):
        err.print(f"[yellow]warning:[/] {note}", highlight=False, soft_wrap=True)
    _report(summary, out, as_json)
    if "summary_error" in summary:   # not saved: printed, so that nothing is lost
        err.print(f"[bold red]error:[/] {escape(summary['summary_error'])}", highlight=False,
                  soft_wrap=True)
        if not as_json:
            sys.stderr.write(json_text({k: v for k, v in summary.items()
                                        if k not in ("config", "spec")}) + "\n")
    if rerun == "serve":        # the run is over and reported; the server stays for viewers
        sys.stdout.flush()
        _keep_serving(rerun_port, summary)
    if summary["status"] != "FINISHED":
        raise typer.Exit(1)


def _report(summary: dict, out: Path, as_json: bool) -> None:
    """Print a run's summary: one JSON object, or the table and the deadline report."""
    if as_json:
        _emit({k: v for k, v in summary.items() if k not in ("config", "spec")}, True)
    else:
        console = Console()
        console.print(_summary_table(summary, f"run {summary['run_id']}"))
        t = summary["ticks"]
        if t["paced"] or t.get("simulated_timer"):
            kind = "deadlines" if t["paced"] else "simulated timer"
            console.print(f"{kind}: {t['due']} due, {t['on_time']} on time "
                          f"({100 * t['on_time_ratio']:.2f} %), {t['late']} late, "
                          f"{t['skipped']} skipped; start jitter p50/p99/max "
                          f"{t['jitter_p50_us']:.0f}/{t['jitter_p99_us']:.0f}/"
                          f"{t['jitter_max_us']:.0f} µs", highlight=False)
        print_paths(console, summary, out)
    if summary.get("error") and summary.get("status") != "FINISHED":
        # why it stopped (a driver fault, a missed deadline, a program error), in words
        err.print(f"[bold red]{summary['status'].lower()}:[/] {escape(summary['error'])}",
                  highlight=False, soft_wrap=True)


def _keep_serving(port: int, summary: dict[str, Any]) -> None:
    """After a ``--rerun serve`` run (reported already): one line saying that the run
    ended and where it is served, then serve it until Ctrl-C, SIGTERM or SIGHUP, and stop
    the server's whole process group (nothing is left listening)."""
    import shlex

    from twin.session.run_end import stop_signals
    from twin.telemetry.viewer import rerun_command, running_rerun, stop_rerun

    servers = running_rerun()
    if not servers:
        return
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    try:
        with stop_signals([]):      # before the message: a signal right after it is caught
            err.print(f"run {summary['run_id']} {summary['status'].lower()} after "
                      f"{summary.get('sim_time_s', 0.0):.1f} s simulated; serving it at "
                      f"{url} (view: {shlex.quote(rerun_command())} --connect {url}); "
                      "Ctrl-C to stop", highlight=False, soft_wrap=True)
            for proc in servers:
                proc.wait()
    except KeyboardInterrupt:
        pass
    finally:
        stop_rerun()


@app.command("run")
def run_cmd(
    program: Path | None = typer.Argument(None, help="G-code file; none: the built-in "
                                           "default program."),
    machine: str = MachineOpt,
    controller_model: str | None = ModelOpt,
    profile: str | None = typer.Option(None, help="Acceleration law (trapezoid, parabolic, "
                                       "cosine, cubic, jerk-limited; default: the "
                                       "machine's), or LAW+SHAPER with an input shaper on "
                                       "both axes (zv, mzv, zvd, ei, 2hump-ei, 3hump-ei, "
                                       "none), e.g. trapezoid+ei."),
    planner: PlannerMode | None = typer.Option(None, help="Look ahead over the blocks, or "
                                               "stop at every node (default: the "
                                               "machine's)."),
    dcu_order: int | None = typer.Option(None, "--dcu-order", min=0, max=3,
                                         help="Order of the digital correcting device."),
    period: float | None = typer.Option(None, help="Controller period (s)."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    rerun: str = typer.Option("file", help=RERUN_HELP + "; or spawn (a native viewer; "
                              "without a display: the file only), serve (a gRPC server for "
                              "viewers, kept until Ctrl-C). spawn and serve also write the "
                              "file."),
    rerun_port: int = typer.Option(9876, "--rerun-port", min=1, max=65535, help="Port of the "
                                   "live viewer or server on 127.0.0.1 (spawn, serve)."),
    out: Path = OutOpt,
    as_json: bool = JsonOpt,
    dry_run: bool = typer.Option(False, "--dry-run", help="Plan and interpolate the "
                                 "program against the machine's limits without the drives "
                                 "or the physics: cycle time, path, peaks against the axis "
                                 "limits, extent against the work zone. Never trips."),
    builtin: Builtin = typer.Option("default", "--builtin",
                                    help="Built-in program when no PROGRAM is given."),
    driver: str = typer.Option("sim", "--driver", help="sim (the twin, lock-step) or "
                               "modbus://HOST:PORT[?map=FILE&timeout=S] (real I/O, paced "
                               "in real time)."),
    rt_priority: int = typer.Option(0, "--rt-priority", min=0, max=99, help="With real "
                                    "I/O: SCHED_FIFO priority of the loop (best effort)."),
    set_file: Path | None = typer.Option(None, "--set-file", help="Overrides as a TOML "
                                         "file (e.g. the best.toml of twin tune); --set "
                                         "values win."),
) -> None:
    """Run a program through the full controller on the twin (or real I/O); write .rrd and
    .json."""
    try:
        rerun = rerun_target(rerun, live=True)
    except TwinError as exc:
        fail(exc, as_json)
    _run(program, machine, profile,
         None if planner is None else planner.value, dcu_order, period, sets, rerun, out,
         as_json, dry_run, builtin.value, driver, rt_priority, set_file, controller_model,
         rerun_port)


@app.command()
def demo(machine: str = MachineOpt, out: Path = OutOpt, as_json: bool = JsonOpt,
         controller_model: str | None = ModelOpt) -> None:
    """Run the built-in default program (spline sections, a corner, a circle) with DCU
    order 0 and 3, and print both summaries."""
    from twin.session.run import RunSpec, run

    rows = {}
    for order in (0, 3):
        try:
            with _progress() as bar:
                task = bar.add_task(f"DCU order {order}", total=None)
                result = run(RunSpec(machine=machine, controller_model=controller_model,
                                     dcu_order=order), out_dir=out, keep_record=False,
                             progress=lambda t, _m, task=task, bar=bar, o=order:
                             bar.update(task, description=f"DCU {o}: {t:.1f} s"))
        except TwinError as exc:
            fail(exc, as_json)
        rows[order] = result.summary
        if not as_json:
            Console().print(_summary_table(result.summary, f"default program, {machine}, "
                                                           f"DCU order {order}"))
            print_paths(Console(), result.summary, out)
    _emit({"runs": {str(k): {kk: vv for kk, vv in v.items() if kk not in ("config", "spec")}
                    for k, v in rows.items()}}, as_json)


@app.command()
def view(
    recording: Path = typer.Argument(..., exists=True, dir_okay=False,
                                     help="A .rrd file written by twin run."),
    web: bool = typer.Option(False, "--web", help="Serve the bundled web viewer on "
                             "localhost instead of opening the native viewer."),
    port: int = typer.Option(9090, min=1, max=65535, help="Web viewer port (with --web)."),
    grpc_port: int = typer.Option(9876, "--grpc-port", min=1, max=65535,
                                  help="Port of the gRPC server that serves the recording "
                                  "to the viewer."),
) -> None:
    """Open a recording in the rerun viewer (native, or --web in a browser); every listener
    binds 127.0.0.1."""
    from twin.session.run_end import stop_signals
    from twin.telemetry.viewer import open_recording

    try:
        with stop_signals([]):
                code = open_recording(recording, web=web, web_port=port, grpc_port=grpc_port,
                                  announce=lambda text: err.print(text, highlight=False,
                                                                  soft_wrap=True))
    except TwinError as exc:
        fail(exc)
    raise typer.Exit(code)


@app.command()
def machines(
    as_json: bool = JsonOpt,
    diff: tuple[str, str] | None = typer.Option(
        None, "--diff", help="Show where two machine files (presets or TOML) differ: "
        "--diff A B."),
    fields: str | None = typer.Option(
        None, "--fields", metavar="MACHINE", help="Every field of MACHINE (a preset or a "
        "TOML file) with its value, unit, allowed range and meaning."),
) -> None:
    """List the machine presets and their key figures, compare two machines, or show every
    field of one with its range."""
    if diff is not None:
        _machine_diff(*diff, as_json)
        return
    if fields is not None:
        _machine_fields(fields, as_json)
        return
    rows = []
    for name in available_machines():
        try:
            cfg = load_machine(name)
        except TwinError as exc:
            fail(exc, as_json)
        ax = cfg.axes["x"]
        rows.append({
            "name": name,
            "description": cfg.description,
            "converter": ax.converter.kind,
            "transmission": ax.transmission.kind,
            "counts_per_um": ax.counts_per_metre * 1e-6,
            "max_feed_mm_per_min": cfg.controller.limits.max_velocity * 60e3,
            "period_ms": cfg.controller.period * 1e3,
        })
    if as_json:
        _emit({"machines": rows}, True)
        return
    from rich import box

    table = Table(title="machines", box=box.SIMPLE_HEAD)
    headers = {"name": "machine", "converter": "converter", "transmission": "transmission",
               "counts_per_um": "counts\nper µm", "max_feed_mm_per_min": "max feed\n(mm/min)",
               "period_ms": "period\n(ms)"}
    keys = [k for k in rows[0] if k != "description"]
    for key in keys:
        table.add_column(headers.get(key, key), no_wrap=True,
                         justify="right" if isinstance(rows[0][key], float) else "left")
    for r in rows:
        table.add_row(*(f"{r[k]:g}" if isinstance(r[k], float) else str(r[k]) for k in keys))
    Console().print(table)


def _machine_fields(machine: str, as_json: bool) -> None:
    """``twin machines --fields M``: every leaf with its value, unit, range and meaning."""
    from twin.config.loader import flatten
    from twin.config.quantities import display_unit
    from twin.config.schema import field_meta, range_text

    try:
        cfg = load_machine(machine)
    except TwinError as exc:
        fail(exc, as_json)
    rows = []
    for path, value in flatten(cfg).items():
        meta = field_meta(path)
        shown = display_unit(meta)
        rows.append({"field": path, "value": value, "unit": meta.get("unit", ""),
                     "display_unit": shown, "range": range_text(meta),
                     "meaning": meta.get("doc", "")})
    if as_json:
        _emit({"machine": cfg.name, "fields": rows}, True)
        return
    table = Table(title=f"{cfg.name}: fields")
    for key in ("field", "value", "range", "meaning"):
        table.add_column(key, overflow="fold")
    for r in rows:
        value = f"{r['value']:g}" if isinstance(r["value"], float) else str(r["value"])
        rng = r["range"] or r["unit"]
        if r["display_unit"]:
            rng += f"; --set in {r['display_unit']}, with the unit"
        table.add_row(r["field"], value, rng, r["meaning"])
    Console().print(table)


def _machine_diff(a: str, b: str, as_json: bool) -> None:
    """``twin machines --diff A B``: every field whose value differs, with its unit."""
    try:
        ma, mb = load_machine(a), load_machine(b)
    except TwinError as exc:
        fail(exc, as_json)
    rows = [{"field": path, "unit": field_unit(path), a: va, b: vb}
            for path, va, vb in diff_machines(ma, mb)]
    if as_json:
        _emit({"a": a, "b": b, "differences": rows}, True)
        return
    if not rows:
        Console().print(f"{a} and {b} are the same machine (names and descriptions aside)")
        return
    table = Table(title=f"{a} vs {b}: {len(rows)} differences")
    for col in ("field", a, b, "unit"):
        table.add_column(col, justify="right" if col in (a, b) else "left")
    for r in rows:
        table.add_row(r["field"], _cell(r[a]), _cell(r[b]), r["unit"])
    Console().print(table)


def _cell(value: Any) -> str:
    if value is None:
        return "—"
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _register_more() -> None:
    """Commands that live in their own modules (imported lazily by their functions)."""
    from twin.cli import compare, hil, identify, manual, measure, runs, shaper, tune

    manual.register(app)
    hil.register(app)
    compare.register(app)
    tune.register(app)
    identify.register(app)
    measure.register(app)
    runs.register(app)
    shaper.register(app)


_register_more()
interrupts.honour()   # a Ctrl-C dropped during the imports ends the command now

def entry() -> None:
    """The ``twin`` entry point. Click's usage errors (an unknown option, a value that is
    not one of the choices, a missing argument) end like every other bad input: one line
    ``error: ...`` naming the option, exit 2, no usage box."""
    try:
        code = app(standalone_mode=False)
    except typer.Abort:
        raise SystemExit(130) from None
    except typer.TyperException as exc:    # typer's own click: a usage error
        from twin.cli.common import usage_text

        err.print(f"[bold red]error:[/] {escape(usage_text(exc))}", highlight=False,
                  soft_wrap=True)
        raise SystemExit(getattr(exc, "exit_code", 2)) from None
    raise SystemExit(code if isinstance(code, int) else 0)

