"""Writing records: strict JSON, atomic files, output folders checked before anything runs.

Light on purpose (the standard library only): the CLI imports it at start-up to print
``--json`` output, and every run, identification and tuning record goes through it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import sys
import time
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from twin.errors import ConfigError
from twin.nesting import MAX_DEPTH, json_too_deep

__all__ = ["LOCK_NAME", "folder_lock", "json_text", "load_json", "output_dir", "partial_path",
           "plain", "record_id", "write_json_atomic", "write_text_atomic"]

LOCK_NAME = ".job.lock"
"""The lock file a job holds in its output folder (``folder_lock``)."""


def partial_path(path: Path) -> Path:
    """The name ``path`` is written under until it is complete (``<name>.partial``), then
    renamed to ``path`` in one step (summaries, recordings)."""
    return path.with_name(path.name + ".partial")


def record_id(prefix: str = "", *, suffix: int = 6) -> str:
    """A name for a record that sorts by time and does not collide:
    ``<prefix>YYYYmmdd-HHMMSS-<random hex>`` (runs, dry runs, comparisons, identifications)."""
    return f"{prefix}{time.strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:suffix]}"


def output_dir(path: str | Path, field: str = "out") -> Path:
    """The folder ``path``, created if need be, once it is known that files can be written
    in it: checked before a job starts (opens a driver, moves a machine, spends a budget),
    so a bad path costs one line, not a traceback after the work.

    Raises
    ------
    ConfigError
        Naming ``field``: the path is not a folder, cannot be created, or cannot be written
        in (read-only, no permission, no space)."""
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(field, f"{folder} is not a folder")
    dangling = _dangling_link(folder)
    if dangling is not None:   # mkdir would say "File exists", naming nothing
        raise ConfigError(field, f"{dangling} is a symlink to {os.readlink(dangling)}, which "
                          "does not exist: point it at a folder or remove it")
    probe = folder / f".write-check-{os.getpid()}"
    try:
        new = [part for part in (*reversed(folder.parents), folder) if not part.exists()]
        folder.mkdir(parents=True, exist_ok=True)
        _CREATED.extend(new)
        try:
            with open(probe, "wb") as f:
                f.write(b"\0")
        finally:
            probe.unlink(missing_ok=True)
    except OSError as exc:
        raise ConfigError(field, f"cannot write in {folder}: {exc.strerror or exc}") from None
    return folder


_CREATED: list[Path] = []
"""The folders ``output_dir`` created in this process, outermost first."""


def drop_unused_outputs() -> None:
    """Remove the folders ``output_dir`` created that are still empty, innermost first:
    a command that refuses its input leaves nothing behind, not even the folder it made
    for its results. A folder that held anything, or was there before, stays."""
    while _CREATED:
        folder = _CREATED.pop()
        try:
            folder.rmdir()              # only an empty folder goes
        except OSError:
            pass


def forget_outputs() -> None:
    """Forget the folders made so far (``drop_unused_outputs`` leaves them): a command
    starting in a process that ran others answers only for its own."""
    _CREATED.clear()


def _dangling_link(folder: Path) -> Path | None:
    """The first part of ``folder`` (from the root down) that is a symlink to nothing."""
    for part in (*reversed(folder.parents), folder):
        if part.is_symlink() and not part.exists():
            return part
        if not part.exists():
            return None
    return None


@contextlib.contextmanager
def folder_lock(folder: str | Path, field: str = "out") -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (an advisory ``flock`` on its ``LOCK_NAME``) for
    the life of a job: a second job into the same folder is refused instead of both
    writing the same files. The lock goes with the process, so a killed job leaves none.

    Raises
    ------
    ConfigError
        Naming ``field``: another process holds the folder (its pid, if it wrote one)."""
    try:
        import fcntl
    except ImportError:   # no flock (Windows): no lock, as before
        yield Path(folder)
        return
    path = Path(folder) / LOCK_NAME
    handle = open(path, "a+", encoding="utf-8")   # held until the job ends
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "?"
            raise ConfigError(field, f"{folder} is in use by another job (pid {holder}); "
                              "give this one its own --out") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield Path(folder)
    finally:
        handle.close()   # releases the lock


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace``: a reader sees the
    old file or the whole new one, never half of it."""
    path = Path(path)
    tmp = partial_path(path)
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)   # no .partial left behind (a full disk, a signal)
        raise
    return path


def write_json_atomic(path: str | Path, obj: Any, *, indent: int | None = 2) -> Path:
    """Write ``obj`` as strict JSON (``json_text``) to ``path`` atomically
    (``write_text_atomic``)."""
    return write_text_atomic(path, json_text(obj, indent=indent) + "\n")


def json_text(obj: Any, *, indent: int | None = None) -> str:
    """``obj`` as strict JSON (RFC 8259): NaN and ±inf become ``null`` (Python's ``json``
    would write ``NaN``, which strict parsers refuse); numpy scalars and arrays, dataclasses
    and paths become plain values; anything else its ``str``."""
    return json.dumps(plain(obj), indent=indent, allow_nan=False, ensure_ascii=False)


def load_json(text: str, where: str, *, first_line: int = 1, max_depth: int = MAX_DEPTH
              ) -> Any:
    """``json.loads(text)`` with its nesting bounded: a text that nests more than
    ``max_depth`` arrays and objects is refused before it is parsed (Python's parser would
    recurse into it and end in a ``RecursionError``).

    Parameters
    ----------
    text : str
        The JSON text.
    where : str
        The file (or file and line) it comes from, for the message.
    first_line : int
        Line number of the text's first line in that file.

    Raises
    ------
    ConfigError
        Naming ``where``, the line and the column where the nesting passes the limit.
    json.JSONDecodeError
        Not JSON (as ``json.loads``).
    """
    deep = json_too_deep(text, max_depth)
    if deep is None:
        try:
            return json.loads(text)
        except RecursionError:      # cannot happen below MAX_DEPTH; never a traceback
            deep = None
    place = "" if deep is None else (f"line {deep.line + first_line - 1}, column "
                                     f"{deep.column}: ")
    raise ConfigError(where, f"{place}nested deeper than {max_depth} levels of arrays and "
                      "objects (no record of xy-twin nests more than 5)")


def plain(obj: Any) -> Any:
    """``obj`` with only JSON's own types: dict (str keys), list, str, int, float (finite),
    bool, None."""
    if obj is None or isinstance(obj, (bool, str, int)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [plain(v) for v in obj]
    np = sys.modules.get("numpy")   # no numpy value can exist unless numpy was imported
    if np is not None:
        if isinstance(obj, np.ndarray):
            return plain(obj.tolist())
        if isinstance(obj, np.generic):
            return plain(obj.item())
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return plain(dataclasses.asdict(obj))
    return str(obj)
