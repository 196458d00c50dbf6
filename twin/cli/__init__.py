"""The ``twin`` command: the composition root, where a machine, a program, a driver and the
telemetry are put together for each command (``main``: run, demo, view, machines,
experiment; the other commands in their own modules, registered by ``main``).

``python -m twin.cli`` is the same as ``twin``.
"""

from twin.cli.main import app, entry

__all__ = ["app", "entry"]
