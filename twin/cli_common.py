"""What every ``twin`` command shares: the stderr console and the one way to fail.

Human output goes to stderr (tables may go to stdout when no ``--json`` is asked for);
``--json`` prints exactly one JSON object on stdout; bad input exits with code 2 and a
message naming the place.
"""

from __future__ import annotations

import typer
from rich.console import Console

__all__ = ["err", "fail"]

err = Console(stderr=True)
"""Console on stderr for messages, progress and errors."""


def fail(exc: BaseException) -> None:
    """Print ``exc`` (which names its place) on stderr and exit with code 2."""
    err.print(f"[bold red]error:[/] {exc}", highlight=False)
    raise typer.Exit(2)
