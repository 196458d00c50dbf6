"""How a run ends: the stop signals that take the one shutdown path (Ctrl-C, SIGTERM,
SIGHUP), a signal held while the record is written, and the final status a record carries
(never a state in progress).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from twin.controller.controller import ControllerStatus
from twin.system import interrupts

if TYPE_CHECKING:
    from twin.session.setup import RunResult

__all__ = ["READY", "STOP_SIGNALS", "RunInterrupted", "Terminated", "deferred_signals",
           "final_status", "raise_caught", "signal_name", "stop_signals"]

READY = (ControllerStatus.IDLE, ControllerStatus.FINISHED)
"""Controller states at rest for good (a run that ends in one has nothing in progress)."""

STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, n))
"""The signals that stop a run the one way: Ctrl-C, ``kill``/systemd/``docker stop``
(SIGTERM), a closed terminal (SIGHUP)."""


class Terminated(KeyboardInterrupt):
    """A stop signal, raised in the main thread as KeyboardInterrupt is: every stop signal
    takes the same path (safe stop, record written)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class RunInterrupted(KeyboardInterrupt):
    """A stop signal arrived while the run record was being written. The record is
    complete (``result``); the caller reports it, then honours the signal (``signum``)."""

    def __init__(self, result: RunResult, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.result, self.signum = result, signum


def signal_name(exc: BaseException) -> str:
    """How an interruption is named in a record: ``Ctrl-C``, or the signal's name."""
    if isinstance(exc, Terminated) and exc.signum != signal.SIGINT:
        return signal.Signals(exc.signum).name
    return "Ctrl-C"


def final_status(status: ControllerStatus, aborted: str | None, max_time: float,
                 io_fault: tuple[str, str] | None = None) -> dict[str, Any]:
    """How a run ended, for its record: ``status`` is FINISHED, ABORTED (``aborted`` says
    why: a signal, an error), FAULT (``fault`` names the controller's latched fault, or
    ``io_fault``'s kind: ``DRIVER`` for the machine's I/O, ``DEADLINE`` for the deadline
    policy; its message goes into ``error``) or TIMEOUT (``timeout`` says which limit);
    never a state in progress. ``controller_status`` keeps the controller's own last
    state."""
    out: dict[str, Any] = {"status": "FINISHED", "aborted": aborted,
                           "controller_status": status.name}
    if aborted is not None:
        out["status"] = "ABORTED"
    elif io_fault is not None:
        out["status"] = "FAULT"
        out["fault"] = io_fault[0]
    elif status >= ControllerStatus.LIMIT_TRIP:
        out["status"] = "FAULT"
        out["fault"] = status.name
    elif status not in READY:
        out["status"] = "TIMEOUT"
        out["timeout"] = (f"max_time ({max_time:g} s) reached while the controller was "
                          f"{status.name}")
    return out


@contextlib.contextmanager
def _handling(signals: tuple[int, ...], handler: Callable[[int, Any], None]
              ) -> Iterator[None]:
    """``handler`` for ``signals`` while inside, the previous handlers afterwards (nothing
    outside the main thread, where Python takes no signal handlers)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


@contextlib.contextmanager
def stop_signals(caught: list[int]) -> Iterator[None]:
    """While the loop runs: a stop signal is appended to ``caught`` and raised as
    ``Terminated``. The exception can be lost: a handler runs wherever the main thread is,
    and an exception raised inside a C callback (numba compiling a kernel and writing its
    cache through an LLVM callback, say) is printed and dropped. So the loop also checks
    ``caught`` at its checkpoints (``raise_caught``) and the signal is never lost. A Ctrl-C
    the command recorded while it started, whose exception was dropped
    (``twin.system.interrupts``), is raised here at once."""
    def stop(signum: int, _frame: Any) -> None:
        caught.append(signum)
        raise Terminated(signum)

    with _handling(STOP_SIGNALS, stop):
        dropped = interrupts.take()
        if dropped is not None:
            caught.append(dropped)
            raise Terminated(dropped)
        yield


def raise_caught(caught: list[int]) -> None:
    """Raise ``Terminated`` for a stop signal whose handler's exception was lost."""
    if caught:
        raise Terminated(caught[0])


def deferred_signals(caught: list[int]) -> contextlib.AbstractContextManager[None]:
    """While the record is written: the stop signals are held, appended to ``caught`` (the
    caller raises ``RunInterrupted`` once the record is complete)."""
    return _handling(STOP_SIGNALS, lambda signum, _frame: caught.append(signum))
