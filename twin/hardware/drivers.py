"""Open a machine's I/O from a driver URL (``twin run --driver URL``).

``modbus://HOST:PORT[?map=FILE&timeout=S&retries=N&reconnects=N&connect_timeout=S]``
opens a ``ModbusDriver`` on a Modbus/TCP I/O module (or on ``twin hil-server``):

* ``map``: register map TOML file (default: the documented default map);
* ``timeout``: answer timeout of each request (s; default 4 controller periods, ≥ 10 ms);
* ``retries``: re-sends after a timeout within a tick (default 0);
* ``reconnects``: attempts to re-establish a lost connection before failing (default 0);
* ``connect_timeout``: how long opening keeps trying to connect (s; default 2).

The twin itself (``"sim"``) is not opened here: ``twin.session.run.prepare`` builds it in lock-step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from twin.config import AXES, MachineConfig
from twin.controller.io import MachineIO
from twin.errors import ConfigError
from twin.hardware.modbus import ModbusDriver
from twin.hardware.register_map import load_register_map

__all__ = ["DriverUrl", "open_driver", "parse_driver_url"]

_USAGE = "modbus://HOST:PORT[?map=FILE&timeout=S&retries=N&reconnects=N&connect_timeout=S]"
_FLOATS = ("timeout", "connect_timeout")
_INTS = ("retries", "reconnects")


@dataclass(frozen=True)
class DriverUrl:
    """A parsed driver URL.

    Attributes
    ----------
    scheme : str
        ``"modbus"``.
    host : str
    port : int
    options : dict
        ``map`` (str), ``timeout``/``connect_timeout`` (float, s), ``retries``/``reconnects``
        (int); only those given.
    """

    scheme: str
    host: str
    port: int
    options: dict[str, Any] = field(default_factory=dict)


def parse_driver_url(url: str) -> DriverUrl:
    """Parse and validate a driver URL; ``ConfigError`` naming ``driver`` (or
    ``driver.OPTION``) and the expected form on any mistake."""
    parts = urlsplit(url)
    if parts.scheme != "modbus":
        raise ConfigError("driver", f"unknown driver {url!r}; valid: sim, {_USAGE}")
    try:
        port = parts.port
    except ValueError:
        port = -1
    if not parts.hostname or port is None or not 0 < port < 65536:
        raise ConfigError("driver", f"{url!r} needs a host and a port 1 … 65535: {_USAGE}")
    options: dict[str, Any] = {}
    for key, value in parse_qsl(parts.query, keep_blank_values=True):
        name = f"driver.{key}"
        if key == "map":
            options[key] = value
        elif key in _FLOATS:
            try:
                number = float(value)
            except ValueError:
                number = math.nan
            if not (math.isfinite(number) and number > 0):
                raise ConfigError(name, f"must be a number of seconds > 0, got {value!r}")
            options[key] = number
        elif key in _INTS:
            if not value.isdigit():
                raise ConfigError(name, f"must be a whole number >= 0, got {value!r}")
            options[key] = int(value)
        else:
            raise ConfigError(name, f"unknown option; valid: map, {', '.join(_FLOATS)}, "
                              f"{', '.join(_INTS)}")
    return DriverUrl(parts.scheme, parts.hostname, port, options)


PLAUSIBLE_MARGIN = 2.0
"""A counter may step by up to this many times its axis' top speed over the time between two
reads (plus a count or two) before the step is taken for a corrupted answer."""


def open_driver(url: str, cfg: MachineConfig) -> MachineIO:
    """Open the machine I/O that ``url`` names, for machine ``cfg``.

    Raises
    ------
    ConfigError
        A malformed URL, a bad register map, or a machine whose encoders are wider than the
        map's 32-bit counters.
    DriverError
        The module cannot be reached or refuses the safe initial state.
    """
    spec = parse_driver_url(url)
    for a in AXES:
        bits = cfg.axes[a].encoder.bits
        if bits > 32:
            raise ConfigError(f"axes.{a}.encoder.bits", f"the Modbus map carries 32-bit "
                              f"counters; a {bits}-bit encoder cannot be read through it")
    opts = dict(spec.options)
    path = opts.pop("map", None)
    rmap = load_register_map(str(path) if path else None)
    opts.setdefault("timeout", max(4.0 * cfg.controller.period, 0.01))
    # how fast a counter may plausibly move: each axis' top speed, with a margin
    plausible = [PLAUSIBLE_MARGIN * cfg.axes[a].limits.max_velocity
                 * cfg.axes[a].counts_per_metre for a in AXES]
    return ModbusDriver(spec.host, spec.port, register_map=rmap, counts_per_s=plausible,
                        counter_bits=[cfg.axes[a].encoder.bits for a in AXES],
                        dacs=[cfg.axes[a].dac for a in AXES], **opts)
