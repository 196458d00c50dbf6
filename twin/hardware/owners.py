"""Who may claim the outputs of the twin's I/O module (``twin hil-server``).

By default anybody may: the first client to feed the watchdog owns the outputs until it
disconnects or the watchdog trips, as an I/O module without an access list (Modbus/TCP
itself has no authentication). An access list — ``hil.owners`` in the machine file, or
``twin hil-server --owner HOST`` — restricts this to the hosts, addresses and networks it
names, as the IP filters of real I/O modules do: another client may still read every input,
but each of its output writes (references, watchdog, enable) is refused with Modbus
exception 1 (illegal function), so it can neither claim the outputs nor feed their watchdog.
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Callable, Sequence
from typing import Any

from twin.errors import ConfigError

__all__ = ["Owners", "client_host"]

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Resolve = Callable[[str], list[str]]


def _resolve(host: str) -> list[str]:
    """The addresses of ``host`` (a name or an address)."""
    return sorted({str(info[4][0]) for info in
                   socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)})


def _address(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address:
    address = ipaddress.ip_address(text.split("%", 1)[0])      # no IPv6 zone
    mapped = getattr(address, "ipv4_mapped", None)             # ::ffff:10.0.0.5
    return mapped if mapped is not None else address


class Owners:
    """The clients that may claim the outputs.

    Parameters
    ----------
    entries : sequence of str
        Host names, addresses or networks (``10.0.0.0/24``); empty: any client.
    field : str
        Where the entries come from, for errors (``hil.owners``, ``--owner``).
    resolve : callable, optional
        Host name → addresses (default: the system's resolver); injected for tests.

    Raises
    ------
    ConfigError
        Naming ``field`` and the entry: a network that is not one, a host that does not
        resolve.
    """

    def __init__(self, entries: Sequence[str] = (), *, field: str = "hil.owners",
                 resolve: Resolve = _resolve):
        self.entries = tuple(entries)
        self.networks: list[Network] = []
        for i, entry in enumerate(self.entries):
            where = f"{field}[{i}]" if field == "hil.owners" else field
            try:
                if "/" in entry:
                    self.networks.append(ipaddress.ip_network(entry, strict=False))
                    continue
                addresses = resolve(entry)
            except (ValueError, OSError, UnicodeError) as exc:
                raise ConfigError(where, f"{entry!r} is not a host, an address or a network "
                                  f"that resolves: {exc}") from None
            self.networks += [ipaddress.ip_network(_address(a)) for a in addresses]

    def allows(self, host: str | None) -> bool:
        """Whether a client at ``host`` (its address; None: not known) may claim the
        outputs."""
        if not self.entries:
            return True
        if host is None:
            return False
        try:
            address = _address(host)
        except ValueError:
            return False
        return any(address in network for network in self.networks)

    def describe(self) -> str:
        """The list for a message: ``first come`` or its entries."""
        return ", ".join(self.entries) if self.entries else "first come"


def client_host(client: Any) -> str | None:
    """The address a connection comes from (its ``host``; None for a direct call)."""
    return getattr(client, "host", None)
