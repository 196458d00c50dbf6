"""Telemetry sinks (rerun) behind a small ``Sink`` protocol."""
