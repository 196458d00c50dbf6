"""A Ctrl-C that arrives while a command starts is never lost.

Python raises ``KeyboardInterrupt`` wherever the main thread is when SIGINT arrives. Inside
a callback (importlib's module-lock weakref callback during an import, a finaliser, numba
loading its cache through a C callback) the exception is printed as "Exception ignored in"
and dropped, and the command then runs on as if nothing had happened (a 60 s program ran
to its end after a Ctrl-C at start-up).

So the ``twin`` command installs, before its heavy imports, a handler that also *records*
the signal (``install``). An exception the interpreter drops is then not lost:

- while the command imports, the handler ends it quietly (exit 128 + signal); if that
  exit is dropped, the command leaves as soon as the imports are done (``honour``);
- afterwards the handler raises ``KeyboardInterrupt`` as Python's own does (click turns it
  into exit 130), and a run's own handlers take any recorded signal that was dropped
  (``take``: ``twin.session.run_end.stop_signals`` raises it at once, before anything is
  written).

A dropped exception of this handler is not printed: the signal is honoured instead. Only
SIGINT needs this: SIGTERM and SIGHUP end the process by default until a run installs its
handlers. Nothing is installed in a process that replaced Python's SIGINT handler itself
(a test runner, an embedding application).
"""

from __future__ import annotations

import signal
import sys
from typing import Any

__all__ = ["honour", "install", "take"]

_PENDING: list[int] = []
_STARTING = [True]
_PREVIOUS_HOOK = sys.unraisablehook


def _record(signum: int, frame: Any) -> None:
    _PENDING.append(signum)
    if _STARTING[0]:
        raise SystemExit(128 + signum)
    signal.default_int_handler(signum, frame)


def _quiet(unraisable: Any) -> None:
    """The interpreter's hook for exceptions it drops: ours are recorded, not printed."""
    if _PENDING and isinstance(unraisable.exc_value, KeyboardInterrupt | SystemExit):
        return
    _PREVIOUS_HOOK(unraisable)


def install() -> None:
    """Record SIGINT from now on (see the module doc), if Python's own handler is the one
    in place."""
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _record)
        sys.unraisablehook = _quiet


def honour() -> None:
    """The command has started: leave now if a signal came while it was starting (its exit
    was dropped), else raise ``KeyboardInterrupt`` for the next one, as Python does."""
    if _PENDING:
        raise SystemExit(128 + _PENDING[-1])
    _STARTING[0] = False


def take() -> int | None:
    """A signal recorded and not yet honoured (its exception dropped), or None; it is
    honoured by the caller from now on."""
    if not _PENDING:
        return None
    signum = _PENDING[-1]
    _PENDING.clear()
    return signum
