"""Telemetry sinks behind a small ``Sink`` protocol: ``NullSink`` (default) and
``RerunSink`` (``.rrd`` files, spawned or served viewers). Imports rerun lazily so that
runs without telemetry never load it."""

from twin.telemetry.sink import NullSink, Sink

__all__ = ["NullSink", "Sink"]
