"""A throwaway PostgreSQL server for the tests: ``initdb`` and ``pg_ctl`` in a temporary
directory, listening on 127.0.0.1 (an ephemeral port) with password authentication, stopped
and removed afterwards.

``initdb`` refuses to run as root, and CI runs as root: then the server runs as the
``postgres`` user of the Debian package (its files are handed to it). Binaries that cannot be
found are a failure with an explanation, never a skip.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

USER, PASSWORD, DATABASE = "twin", "s3cret-pw", "tune"


def _binary(name: str) -> str:
    found = shutil.which(name) or next(iter(sorted(glob.glob(
        f"/usr/lib/postgresql/*/bin/{name}"), reverse=True)), None)
    if found is None:
        pytest.fail(f"PostgreSQL's {name} is not installed: the distributed-study tests need "
                    "a real server (Debian: apt install postgresql; initdb and pg_ctl on the "
                    "PATH or in /usr/lib/postgresql/*/bin)")
    return found


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass(frozen=True)
class Server:
    host: str
    port: int

    def url(self, user: str = USER, password: str = PASSWORD, database: str = DATABASE,
            ) -> str:
        return f"postgresql://{user}:{password}@{self.host}:{self.port}/{database}"

    def create_database(self, name: str) -> str:
        """A new empty database; returns its URL."""
        import psycopg

        with psycopg.connect(host=self.host, port=self.port, user=USER, password=PASSWORD,
                             dbname="postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(database=name)


@contextlib.contextmanager
def postgres_server() -> Iterator[Server]:
    """Start a server, create the database ``tune``; stop and delete it on exit."""
    initdb, pg_ctl = _binary("initdb"), _binary("pg_ctl")
    root = Path(tempfile.mkdtemp(prefix="twin-pg-"))
    as_user = None
    if os.geteuid() == 0:
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            pytest.fail("running as root, and initdb refuses root; the postgres user the "
                        "Debian package creates is missing, so the server has nobody to run "
                        "as")
        os.chown(root, owner.pw_uid, owner.pw_gid)
        as_user = owner.pw_name
    data, log, pwfile = root / "data", root / "server.log", root / "pw"
    pwfile.write_text(PASSWORD)
    if as_user is not None:
        shutil.chown(pwfile, as_user)
    run = {"user": as_user, "capture_output": True, "text": True, "check": False,
           "cwd": root}
    done = subprocess.run([initdb, "-D", str(data), "-U", USER, f"--pwfile={pwfile}",
                           "--auth-local=scram-sha-256", "--auth-host=scram-sha-256",
                           "-E", "UTF8", "--no-sync"], **run)
    if done.returncode != 0:
        shutil.rmtree(root, ignore_errors=True)
        pytest.fail(f"initdb failed ({done.returncode}): {done.stderr.strip()}")
    port = _free_port()
    options = (f"-c listen_addresses=127.0.0.1 -p {port} -k {root} -c fsync=off "
               "-c synchronous_commit=off -c full_page_writes=off")
    done = subprocess.run([pg_ctl, "-D", str(data), "-o", options, "-l", str(log), "-w",
                           "-t", "60", "start"], **run)
    if done.returncode != 0:
        text = log.read_text() if log.exists() else ""
        shutil.rmtree(root, ignore_errors=True)
        pytest.fail(f"pg_ctl start failed ({done.returncode}): {done.stderr.strip()} {text}")
    try:
        server = Server("127.0.0.1", port)
        server.create_database(DATABASE)
        yield server
    finally:
        subprocess.run([pg_ctl, "-D", str(data), "-m", "immediate", "-w", "stop"], **run)
        shutil.rmtree(root, ignore_errors=True)
