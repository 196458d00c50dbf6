"""Who may claim the outputs of ``twin hil-server`` (issue 33): first come by default, or
only the hosts and networks of an access list, checked against an independent bit-level
reference; and the server's log stays free of tracebacks."""

from __future__ import annotations

import contextlib
import ipaddress
import json
import logging
import os
import random
import subprocess
import sys

import pytest
from pymodbus.client import ModbusTcpClient

from twin.errors import ConfigError
from twin.hardware.hil_process import spawn_hil_server
from twin.hardware.hil_server import RateLimitedLog
from twin.hardware.owners import Owners

UNIT = 1


def _inside(address: str, network: str) -> bool:
    """The reference: the address's leading bits equal the network's (IPv4)."""
    base, bits = network.split("/")
    a = int.from_bytes(bytes(int(p) for p in address.split(".")), "big")
    n = int.from_bytes(bytes(int(p) for p in base.split(".")), "big")
    shift = 32 - int(bits)
    return a >> shift == n >> shift


def test_an_access_list_matches_addresses_as_their_bits_say():
    rng = random.Random(33)
    for _ in range(200):
        networks = [f"{rng.randrange(256)}.{rng.randrange(256)}.{rng.randrange(256)}.0/"
                    f"{rng.choice([8, 16, 20, 24, 30, 32])}" for _ in range(rng.randint(1, 3))]
        owners = Owners(networks)
        for _ in range(20):
            net = ipaddress.ip_network(rng.choice(networks), strict=False)
            near = int(net.network_address) + rng.randrange(-3, net.num_addresses + 3)
            address = str(ipaddress.ip_address(near % 2**32))
            expected = any(_inside(address, n) for n in networks)
            assert owners.allows(address) is expected, (address, networks)
            assert owners.allows(f"::ffff:{address}") is expected      # IPv4 over IPv6
    assert Owners().allows(None) and Owners().allows("203.0.113.9")      # first come
    assert not Owners(["127.0.0.1"]).allows(None)                        # who is it?


@pytest.mark.parametrize("entry", ["10.0.0.0/33", "no.such.host.invalid", "1.2.3.4/abc"])
def test_an_entry_that_names_no_client_is_refused_naming_it(entry):
    with pytest.raises(ConfigError) as info:
        Owners(["127.0.0.1", entry], resolve=lambda h: (_ for _ in ()).throw(OSError(h))
               if h.endswith(".invalid") else ["127.0.0.1"])
    assert info.value.field == "hil.owners[1]" and repr(entry) in info.value.message


def test_a_traceback_in_a_message_never_reaches_the_log():
    record = logging.LogRecord("pymodbus", logging.ERROR, __file__, 1,
                               "Datastore unable to fulfill request: %s; %s", (22,
                               "Traceback (most recent call last):\n  File \"x\", line 1"),
                               None)
    assert RateLimitedLog().filter(record)
    assert record.getMessage() == "Datastore unable to fulfill request: 22"


@contextlib.contextmanager
def _client(port: int, source: str):
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=2.0, source_address=(source, 0))
    assert c.connect()
    try:
        yield c
    finally:
        c.close()


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.skipif(sys.platform != "linux", reason="127.0.0.2 is a loopback address on Linux")
def test_the_server_serves_only_its_owners_and_logs_no_traceback(tmp_path):
    """``--owner`` twice: a client outside the list is refused every output write
    (exception 1), function 22 (mask write) is served, the log holds no traceback. Without
    CI also: a controller started while another owner holds the outputs is refused as busy,
    and ``--json`` prints its one object (CI checks that object on a cheaper refusal,
    ``tests/test_cli_hostile_input.py``)."""
    # a watchdog longer than the controller's start: the owner's outputs stay claimed
    with spawn_hil_server("--owner", "127.0.0.1", "--owner", "127.0.0.2",
                          "--watchdog-ms", "120000") as server:
        port = server.info["port"]
        assert server.info["owners"] == ["127.0.0.1", "127.0.0.2"]
        with _client(port, "127.0.0.3") as stranger, _client(port, "127.0.0.2") as owner:
            for answer in (stranger.write_register(2, 7, device_id=UNIT),
                           stranger.write_registers(0, [100, 100, 8], device_id=UNIT),
                           stranger.write_coil(0, True, device_id=UNIT),
                           stranger.mask_write_register(address=2, and_mask=0, or_mask=3,
                                                        device_id=UNIT)):
                assert answer.isError() and answer.exception_code == 1, answer
            assert not stranger.read_input_registers(0, count=6, device_id=UNIT).isError()
            # function 22 (mask write) feeds the watchdog like any write: the owner's
            done = owner.mask_write_register(address=2, and_mask=0, or_mask=5, device_id=UNIT)
            assert not done.isError(), done
            assert owner.read_holding_registers(2, count=1, device_id=UNIT).registers == [5]
            assert not owner.write_coil(0, True, device_id=UNIT).isError()
            if not os.environ.get("CI"):
                _a_second_controller_is_refused_as_busy(server.url, tmp_path)
        stats = server.stop()
        log = server.log()
    assert stats is not None and stats["refused"] >= 4
    assert "Traceback" not in log and "File \"" not in log, log


def _a_second_controller_is_refused_as_busy(url: str, out) -> None:
    """``twin run --driver modbus://… --json`` while another client owns the outputs: exit
    2, one line on stderr, the one JSON object on stdout."""
    done = subprocess.run([sys.executable, "-m", "twin.cli", "run", "--builtin", "tiny",
                           "--driver", url, "--json", "--rerun", "none", "--out", str(out)],
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "DEVICE_BUSY" in lines[0], done.stderr
    answer = json.loads(done.stdout)
    assert answer["status"] == "REFUSED" and "DEVICE_BUSY" in answer["error"]
