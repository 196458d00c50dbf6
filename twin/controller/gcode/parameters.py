"""A program's parameters with LinuxCNC's scopes.

``#1``–``#30`` and names without a leading underscore are local to a subroutine call (a
call's arguments are its ``#1``, ``#2``, …); ``#31``–``#5601`` and names that begin with
``_`` are global. The machine's own parameters (position, offsets, modes) are read through
``system``: callables the interpreter provides.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["Parameters"]


class Parameters:
    """Numbered and named parameters with LinuxCNC's scopes (see the module docstring)."""

    LOCAL = 30
    """``#1``–``#30`` are local to a call."""

    def __init__(self, system: dict[str, Callable[[], float]] | None = None,
                 numbered: dict[int, float] | None = None):
        self.numbered: dict[int, float] = dict(numbered or {})
        self.named: dict[str, float] = {}
        self.scopes: list[tuple[dict[int, float], dict[str, float]]] = [({}, {})]
        self.system = system or {}

    def get(self, key: int | str) -> float | None:
        if isinstance(key, int):
            table = self.scopes[-1][0] if key <= self.LOCAL else self.numbered
            return table.get(key, 0.0)
        if key.startswith("_"):
            if key in self.system:
                return self.system[key]()
            return self.named.get(key)
        return self.scopes[-1][1].get(key)

    def exists(self, name: str) -> bool:
        return self.get(name) is not None

    def set(self, key: int | str, value: float) -> None:
        if isinstance(key, int):
            (self.scopes[-1][0] if key <= self.LOCAL else self.numbered)[key] = value
        elif key.startswith("_"):
            self.named[key] = value
        else:
            self.scopes[-1][1][key] = value

    def enter(self, arguments: tuple[float, ...]) -> None:
        self.scopes.append(({i + 1: value for i, value in enumerate(arguments)}, {}))

    def leave(self) -> None:
        self.scopes.pop()
