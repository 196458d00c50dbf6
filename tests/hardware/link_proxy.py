"""A TCP proxy on loopback between a Modbus client and server, for fault tests: it delays
every chunk by ``delay`` seconds one way, and passes the server's answers through
``spoil`` (which may corrupt one)."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable


class LinkProxy:
    """Listens on 127.0.0.1 (``port``) and forwards to ``upstream_port``."""

    def __init__(self, upstream_port: int, *, delay: float = 0.0,
                 spoil: Callable[[bytes], bytes] | None = None):
        self.delay, self.upstream, self.spoil = delay, upstream_port, spoil
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.sock.accept()
            except OSError:
                return
            server = socket.create_connection(("127.0.0.1", self.upstream))
            threading.Thread(target=self._pump, args=(client, server, None),
                             daemon=True).start()
            threading.Thread(target=self._pump, args=(server, client, self.spoil),
                             daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket,
              spoil: Callable[[bytes], bytes] | None) -> None:
        try:
            while data := src.recv(65536):
                if self.delay:
                    time.sleep(self.delay)
                dst.sendall(spoil(data) if spoil is not None else data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                s.close()

    def close(self) -> None:
        self.sock.close()
