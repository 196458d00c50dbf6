"""Run a program's lines: parameters, O-word control flow and subroutines around the block
interpreter.

The runner reads one line at a time, as LinuxCNC's interpreter does, and keeps in memory
only what a jump back may need:

* the lines of a loop (``while``/``endwhile``, ``do``/``while``, ``repeat``/``endrepeat``)
  while it runs, from its first line (``Tape``); a program without loops streams in constant
  memory;
* the body of every subroutine defined in the program so far (``O<name> sub`` …
  ``O<name> endsub``), read when its definition is passed over. A ``call`` of a name not
  defined in the program runs ``name.ngc`` from the program's folder or the subroutine
  folders (``twin.controller.gcode.subfiles``: nothing outside them is read), streamed from
  the file at every call like the main program, in constant memory.

Scopes as in LinuxCNC: ``#1``–``#30`` and names without a leading underscore are local to a
call (a call's arguments are its ``#1``, ``#2``, …); ``#31``–``#5601`` and names that begin
with ``_`` are global. ``endsub [v]`` or ``return [v]`` sets ``#<_value>`` and
``#<_value_returned>``.

Bounds: each loop may run at most ``Limits.loop_iterations`` times and calls may nest
``Limits.call_depth`` deep; past either the program stops with a ``GCodeError`` at the line
that passed it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from functools import partial
from typing import IO

from twin.controller.gcode.expr import OWord, read_statement
from twin.controller.gcode.lexer import clean, words
from twin.controller.gcode.parameters import Parameters
from twin.controller.gcode.shapes import Shapes
from twin.controller.gcode.subfiles import Folders, SubFile, name_problem, open_body
from twin.controller.gcode.tape import Tape
from twin.errors import ConfigError, GCodeError

__all__ = ["Limits", "Runner"]

_OWORD_LINE = re.compile(r"[ \t]*(?:N[ \t]*[0-9.]+[ \t]*)?O[ \t]*(<[^>]*>|[0-9][0-9 \t]*)"
                         r"[ \t]*([A-Z]+)")


@dataclass(frozen=True, slots=True)
class Limits:
    """What stops a runaway program.

    Attributes
    ----------
    loop_iterations : int
        Most passes of one loop (each ``while``, ``do`` or ``repeat`` counted on its own).
    call_depth : int
        Most subroutine calls open at once (recursion included).
    subroutine_path : tuple of str
        Folders searched for ``name.ngc`` when ``O<name> call`` names a subroutine the
        program does not define, after the program's own folder
        (``controller.gcode.subroutine_path``).
    """

    loop_iterations: int = 100_000
    call_depth: int = 64
    subroutine_path: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("loop_iterations", "call_depth"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"gcode.{name}", f"must be a whole number >= 1, got "
                                                   f"{value!r}")


@dataclass(slots=True)
class _Control:
    """An open ``while``, ``do``, ``repeat`` or ``if``."""

    kind: str
    label: str
    line: int
    column: int
    source: str
    pos: int = -1             # loops: the line to go back to (held on the tape)
    passes: int = 0
    remaining: int = 0        # repeat
    taken: bool = False       # if: a branch has run


@dataclass(slots=True)
class _Frame:
    """The main program or one open call."""

    tape: Tape
    file: str | None
    label: str | None = None
    controls: list[_Control] = field(default_factory=list)
    handle: IO[str] | None = None       # a called file's, closed when the call returns


@dataclass(slots=True)
class _Sub:
    lines: list[str] | None              # None: read from ``source`` at every call
    first_line: int
    file: str | None
    source: SubFile | None = None


class Runner:
    """Read a program line by line and hand its blocks to an interpreter.

    Parameters
    ----------
    execute : callable
        ``execute(words, line, source, file)`` runs one block's words and returns its items
        (``Interpreter.execute_words``).
    parameters : Parameters
        The parameter table, shared with the interpreter (system parameters).
    limits : Limits
        Loop, call and search-path bounds.
    folder : str, optional
        The program's folder, searched first for ``name.ngc``.
    fast : (match, run, run_words), optional
        A fast path for the commonest lines: ``match(text)`` (a regex's ``fullmatch``) and
        ``run(found, line)`` returning the item, True (nothing to yield) or None (run the
        line the general way); ``run_words(n, g, x, y, f, line)`` the same for such a line
        written with parameters and expressions, whose shapes are compiled
        (``twin.controller.gcode.shapes``). None: every line the general way (the
        reference).
    """

    def __init__(self, execute: Callable[..., tuple], parameters: Parameters, limits: Limits,
                 folder: str | None = None,
                 fast: tuple[Callable[[str], re.Match[str] | None], Callable, Callable] | None
                 = None):
        self._execute = execute
        self._fast = fast
        self.parameters = parameters
        self.limits = limits
        self._folders = Folders(([folder] if folder else []) + list(limits.subroutine_path))
        self._subs: dict[str, _Sub] = {}
        self._frames: list[_Frame] = []

    # -- errors -------------------------------------------------------------------------
    def _error(self, line: int, column: int, message: str, code: str, source: str = "",
               frame: _Frame | None = None) -> GCodeError:
        frame = frame or self._frames[-1]
        return GCodeError(line, column, message, code=code, source=source, file=frame.file)

    # -- the main loop ------------------------------------------------------------------
    def run(self, lines: Iterable[str], started: Callable[[], bool]) -> Iterator[tuple]:
        """Items of every block, in execution order.

        ``started()`` tells whether a block has run (a ``%`` before any opens the tape).
        An error in a called file names that file."""
        try:
            yield from self._run(lines, started)
        except GCodeError as error:
            file = self._frames[-1].file if self._frames else None
            if error.file is not None or file is None:
                raise
            raise GCodeError(error.line, error.column, error.message, code=error.code,
                             source=error.source, file=file) from None
        finally:
            for frame in self._frames:      # the called files still open
                if frame.handle is not None:
                    frame.handle.close()

    def _run(self, lines: Iterable[str], started: Callable[[], bool]) -> Iterator[tuple]:
        tape = Tape(lines)
        self._frames = [_Frame(tape, None)]
        tape_opened = False
        parameters = self.parameters
        match, fast, fast_move = self._fast if self._fast is not None else (None, None, None)
        shapes = Shapes(parameters) if self._fast is not None else None
        while True:
            frame = self._frames[-1]
            text = frame.tape.next()
            if match is not None and text is not None and "[" not in text and "#" not in text:
                found = match(text)
                if found is not None:
                    item = fast(found, frame.tape.line)
                    if item is not None:
                        if item is not True:
                            yield item
                        continue
            if text is None:
                if len(self._frames) > 1:   # a body read to its end has no endsub: return
                    self._return(None)
                    continue
                self._unclosed(frame)
                return
            line = frame.tape.line
            code = clean(text, line) if text else ""
            if not code or code.isspace():
                continue
            if "%" in code and len(self._frames) == 1 and code.lstrip(" \t").startswith("%"):
                if not started() and not tape_opened:
                    tape_opened = True
                    continue
                self._unclosed(frame)
                return
            if "#" in code or "[" in code or "O" in code or "@" in code or "^" in code:
                if shapes is None:
                    statement = read_statement(code, line, text, self._lookup(frame, text),
                                               parameters.exists)
                else:
                    statement = shapes.read(code, line, text,
                                            partial(self._lookup, frame, text))
                    if type(statement) is tuple:        # only N, G, X, Y, F words
                        item = fast_move(*statement, line)
                        if item is not None:
                            if item is not True:
                                yield item
                            continue
                        statement = read_statement(code, line, text,
                                                   self._lookup(frame, text),
                                                   parameters.exists)
                if statement.oword is not None:
                    self._control(statement.oword, line, text)
                    continue
                block_words, assignments = statement.words, statement.assignments
            else:
                block_words, assignments = words(code, line, text), ()
            if block_words:
                yield from self._execute(block_words, line, text, frame.file)
            for assignment in assignments:
                parameters.set(assignment.target, assignment.value)

    def _lookup(self, frame: _Frame, text: str) -> Callable[[int | str, int], float]:
        parameters = self.parameters

        def lookup(key: int | str, column: int) -> float:
            value = parameters.get(key)
            if value is None:
                line = frame.tape.line
                raise self._error(line, column, f"named parameter #<{key}> is not set",
                                  "unset-parameter", text)
            return value
        return lookup

    def _unclosed(self, frame: _Frame) -> None:
        if frame.controls:
            control = frame.controls[-1]
            ends = {"while": "endwhile", "do": "while", "repeat": "endrepeat",
                    "if": "endif"}[control.kind]
            raise self._error(control.line, control.column,
                              f"O{control.label} {control.kind} without its "
                              f"O{control.label} {ends}", "unclosed-block", control.source)

    # -- control statements ---------------------------------------------------------------
    def _control(self, oword: OWord, line: int, text: str) -> None:
        frame = self._frames[-1]
        keyword, label = oword.keyword, oword.label
        controls = frame.controls
        top = controls[-1] if controls else None
        if keyword == "sub":
            if len(self._frames) > 1 and frame.label == label:
                raise self._error(line, oword.column, f"O{label} sub inside its own body",
                                  "bad-block", text)
            self._define(frame, label, line, oword.column, text)
        elif keyword == "call":
            self._call(label, oword.arguments, line, oword.column, text)
        elif keyword in ("endsub", "return"):
            if len(self._frames) == 1:
                raise self._error(line, oword.column, f"O{label} {keyword} outside a "
                                  "subroutine", "bad-block", text)
            self._return(oword.arguments[0] if oword.arguments else None)
        elif keyword == "while" and top is not None and top.kind == "do" \
                and top.label == label:
            self._loop_again(frame, top, oword, line, text)
        elif keyword == "while":
            if not oword.arguments:
                raise self._error(line, oword.column, f"O{label} while needs a condition "
                                  "[...]", "missing-word", text)
            if top is not None and top.kind == "while" and top.label == label \
                    and top.pos == frame.tape.pos - 1:
                control = top                           # back at the top of the loop
            else:
                control = _Control("while", label, line, oword.column, text,
                                   frame.tape.pos - 1)
                frame.tape.mark(control.pos)
                controls.append(control)
            if oword.arguments[0] != 0.0:
                self._count(control, line, text)
            else:
                self._close(frame, control)
                self._skip(frame, label, ("endwhile",), line, oword.column, text)
        elif keyword == "do":
            control = _Control("do", label, line, oword.column, text, frame.tape.pos)
            frame.tape.mark(control.pos)
            controls.append(control)
        elif keyword == "repeat":
            count = round(oword.arguments[0])
            if count <= 0:
                self._skip(frame, label, ("endrepeat",), line, oword.column, text)
                return
            control = _Control("repeat", label, line, oword.column, text, frame.tape.pos,
                               remaining=count)
            frame.tape.mark(control.pos)
            controls.append(control)
        elif keyword in ("endwhile", "endrepeat"):
            kind = "while" if keyword == "endwhile" else "repeat"
            control = self._open(frame, label, (kind,), keyword, line, oword.column, text)
            if kind == "while":
                frame.tape.seek(control.pos)          # the while line tests again
            else:
                control.remaining -= 1
                if control.remaining > 0:
                    self._count(control, line, text)
                    frame.tape.seek(control.pos)
                else:
                    self._close(frame, control)
        elif keyword == "if":
            control = _Control("if", label, line, oword.column, text)
            controls.append(control)
            if oword.arguments[0] != 0.0:
                control.taken = True
            else:
                self._branch(frame, control)
        elif keyword in ("elseif", "else"):
            control = self._open(frame, label, ("if",), keyword, line, oword.column, text)
            if control.taken:
                self._close(frame, control)
                self._skip(frame, label, ("endif",), line, oword.column, text)
            elif keyword == "else" or oword.arguments[0] != 0.0:
                control.taken = True
            else:
                self._branch(frame, control)
        elif keyword == "endif":
            self._close(frame, self._open(frame, label, ("if",), keyword, line, oword.column,
                                          text))
        elif keyword in ("break", "continue"):
            control = self._open(frame, label, ("while", "do", "repeat"), keyword, line,
                                 oword.column, text, inner_ifs=True)
            while controls[-1] is not control:
                self._close(frame, controls[-1])
            if keyword == "break":
                self._close(frame, control)
                ends = {"while": ("endwhile",), "do": ("while",),
                        "repeat": ("endrepeat",)}[control.kind]
                self._skip(frame, label, ends, line, oword.column, text)
            elif control.kind == "repeat":
                control.remaining -= 1
                if control.remaining > 0:
                    self._count(control, line, text)
                    frame.tape.seek(control.pos)
                else:
                    self._close(frame, control)
                    self._skip(frame, label, ("endrepeat",), line, oword.column, text)
            else:
                if control.kind == "do":
                    self._count(control, line, text)
                frame.tape.seek(control.pos)

    def _loop_again(self, frame: _Frame, control: _Control, oword: OWord, line: int,
                    text: str) -> None:
        if not oword.arguments:
            raise self._error(line, oword.column, f"O{oword.label} while closing a do needs "
                              "a condition [...]", "missing-word", text)
        if oword.arguments[0] != 0.0:
            self._count(control, line, text)
            frame.tape.seek(control.pos)
        else:
            self._close(frame, control)

    def _count(self, control: _Control, line: int, text: str) -> None:
        control.passes += 1
        if control.passes > self.limits.loop_iterations:
            raise self._error(control.line, control.column,
                              f"O{control.label} {control.kind} ran more than "
                              f"{self.limits.loop_iterations} times (controller.gcode."
                              "loop_iterations): a runaway loop?", "loop-limit",
                              control.source)

    def _open(self, frame: _Frame, label: str, kinds: tuple[str, ...], keyword: str,
              line: int, column: int, text: str, inner_ifs: bool = False) -> _Control:
        """The open control ``keyword`` belongs to: the innermost one with ``label``."""
        for control in reversed(frame.controls):
            if control.label == label and control.kind in kinds:
                return control
            if not (inner_ifs and control.kind == "if"):
                break
        opening = " or ".join(kinds)
        raise self._error(line, column, f"O{label} {keyword} without an open O{label} "
                          f"{opening}", "unmatched-block", text)

    def _close(self, frame: _Frame, control: _Control) -> None:
        frame.controls.remove(control)
        if control.pos >= 0:
            frame.tape.release(control.pos)

    def _branch(self, frame: _Frame, control: _Control) -> None:
        """Skip an untaken branch up to the next elseif, else or endif of the same label,
        and run that line."""
        text = self._skip(frame, control.label, ("elseif", "else", "endif"), control.line,
                          control.column, control.source)
        line = frame.tape.line
        statement = read_statement(clean(text, line), line, text, self._lookup(frame, text),
                                   self.parameters.exists)
        assert statement.oword is not None
        self._control(statement.oword, line, text)

    def _skip(self, frame: _Frame, label: str, ends: tuple[str, ...], line: int,
              column: int, source: str) -> str:
        """Read forward, evaluating nothing, through the next line ``O<label> <one of
        ends>``; return that line."""
        tape = frame.tape
        while True:
            text = tape.next()
            if text is None:
                raise self._error(line, column, f"O{label}: no matching "
                                  f"{' / '.join('O' + label + ' ' + e for e in ends)} "
                                  "before the end of the program", "unclosed-block",
                                  source, frame=frame)
            if "o" not in text and "O" not in text:
                continue
            found = self._oword_of(text, tape.line)
            if found is not None and found[0] == label and found[1] in ends:
                return text

    @staticmethod
    def _oword_of(text: str, line: int) -> tuple[str, str] | None:
        code = clean(text, line)
        match = _OWORD_LINE.match(code)
        if match is None:
            return None
        label = match.group(1).replace(" ", "").replace("\t", "")
        label = label.lower() if label.startswith("<") else label.lstrip("0") or "0"
        keyword = match.group(2).lower()
        return label, keyword

    # -- subroutines ----------------------------------------------------------------------
    def _define(self, frame: _Frame, label: str, line: int, column: int, text: str) -> None:
        self._subs[label] = _Sub(self._body(frame, label, line, column, text, []), line + 1,
                                 frame.file)

    def _body(self, frame: _Frame, label: str, line: int, column: int, text: str,
              body: list[str] | None) -> list[str] | None:
        """Read the body of ``O<label> sub`` (at ``line``) through its endsub, into
        ``body`` if one is given."""
        tape = frame.tape
        while True:
            row = tape.next()
            if row is None:
                raise self._error(line, column, f"O{label} sub without its O{label} endsub",
                                  "unclosed-block", text)
            if body is not None:
                body.append(row)
            if "o" in row or "O" in row:
                found = self._oword_of(row, tape.line)
                if found is not None and found[0] == label:
                    if found[1] == "endsub":
                        break
                    if found[1] == "sub":
                        raise self._error(tape.line, 1, f"O{label} sub inside the body of "
                                          f"O{label} sub", "bad-block", row)
        return body

    def _call(self, label: str, arguments: tuple[float, ...], line: int, column: int,
              text: str) -> None:
        sub = self._subs.get(label)
        if sub is None:
            sub = self._load(label, line, column, text)
        if len(self._frames) > self.limits.call_depth:
            raise self._error(line, column, f"O{label} call: calls nest deeper than "
                              f"{self.limits.call_depth} (controller.gcode.call_depth): a "
                              "runaway recursion?", "call-depth", text)
        handle = None
        if sub.source is not None:
            handle = self._open_file(sub.source, label, line, column, text)
        self.parameters.enter(arguments)
        self._frames.append(_Frame(Tape(sub.lines if handle is None else handle,
                                        sub.first_line), sub.file, label, handle=handle))

    def _open_file(self, source: SubFile, label: str, line: int, column: int, text: str
                   ) -> IO[str]:
        try:
            return open_body(source)
        except OSError as exc:
            raise self._error(line, column, f"O{label} call: cannot read {source.path}: "
                              f"{exc.strerror or exc}", "unknown-sub", text) from None

    def _load(self, label: str, line: int, column: int, text: str) -> _Sub:
        """Find ``name.ngc`` for ``O<name> call`` (``subfiles``), check that it defines
        the subroutine and that its body ends, and note where the body begins."""
        if not label.startswith("<"):
            raise self._error(line, column, f"O{label} call of a subroutine not defined "
                              "before it", "unknown-sub", text)
        name = label[1:-1]
        problem = name_problem(name)
        if problem is not None:
            raise self._error(line, column, f"O{label} call: {problem}", "unknown-sub", text)
        found = self._folders.find(name)
        if found is None:
            raise self._error(line, column, f"O{label} call: no subroutine {label} in the "
                              f"program and no {name}.ngc in {self._folders.describe()}",
                              "unknown-sub", text)
        with self._open_file(found, label, line, column, text) as handle:
            number = 0
            for row in iter(handle.readline, ""):
                number += 1
                row = row.rstrip("\r\n")
                if ("o" in row or "O" in row) and self._oword_of(row, number) == (label, "sub"):
                    sub = _Sub(None, number + 1, found.path,
                               found._replace(offset=handle.tell(), first_line=number + 1))
                    frame = _Frame(Tape(handle, number + 1), found.path)   # no tell() now
                    self._frames.append(frame)
                    try:
                        self._body(frame, label, number, 1, row, None)
                    finally:
                        self._frames.pop()
                    self._subs[label] = sub
                    return sub
        raise self._error(line, column, f"O{label} call: {found.path} does not define "
                          f"O{label} sub", "unknown-sub", text)

    def _return(self, value: float | None) -> None:
        """Leave the call: its frame, its tape (a called file closed) and its local
        parameters go."""
        frame = self._frames.pop()
        if frame.handle is not None:
            frame.handle.close()
        self.parameters.leave()
        if value is not None:
            self.parameters.set("_value", value)
        self.parameters.set("_value_returned", 0.0 if value is None else 1.0)
