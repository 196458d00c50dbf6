"""Property tests: whatever the text, the reader returns items or raises a placed GCodeError."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from twin.controller.gcode import Interpreter, Move, parse
from twin.errors import GCodeError

VALID = """%
(a program that uses every feature once)
N10 G17 G21 G90 G94 G40 G49 G54 G80
N20 T1 M6 S12000 M3 M8
N30 G0 X-5 Y-5
N40 G1 X20 Y0 F900
N50 G3 X30 Y10 I0 J10
N60 G2 X40 Y0 R-10 ; long way round
N70 G91 G1 X-5 Y-5
N80 G90 G4 P0.25
N90 G20 G1 X0.5 Y0.5 F20
N100 G21 G2 X12.7 Y12.7 I0 J0.0001 P2
N110 G3 I5 J0
N120 M5 M9
N130 M30
%
"""

GCODE_ALPHABET = "GMNXYZIJKRFPST0123456789.+- \t()%;/\neEQ#"
INTERESTING = [0, 1, 2, 3, 4, 5, 6, 17, 18, 19, 20, 21, 30, 40, 49, 54, 80, 90, 91, 93, 94,
               95, -1, 0.5, 1e-9, 0.001, 10, -10, 12.7, 999999999, 1e8, 2.5, 7]


def check_outcome(text: str) -> None:
    """Parse; any exception must be a GCodeError placed inside the text."""
    try:
        program = parse(text)
    except GCodeError as error:
        lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        assert 1 <= error.line <= len(lines)
        assert error.source == lines[error.line - 1]
        assert 1 <= error.column <= max(len(error.source), 1)
        assert error.code and error.message
        return
    for move in program.moves:
        assert all(math.isfinite(v) for v in (*move.start, *move.end))
        assert math.isfinite(move.length) and move.length >= 0.0


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=300))
def test_any_unicode_text(text):
    check_outcome(text)


@given(st.text(alphabet=GCODE_ALPHABET, max_size=300))
def test_gcode_like_text(text):
    check_outcome(text)


@st.composite
def mutated(draw):
    """The valid program with a few random deletions, insertions and replacements."""
    text = VALID
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text) - 1))
        kind = draw(st.sampled_from(("delete", "insert", "replace", "swap-lines")))
        char = draw(st.sampled_from(GCODE_ALPHABET))
        if kind == "delete":
            text = text[:at] + text[at + 1:]
        elif kind == "insert":
            text = text[:at] + char + text[at:]
        elif kind == "replace":
            text = text[:at] + char + text[at + 1:]
        else:
            lines = text.split("\n")
            i = draw(st.integers(0, len(lines) - 1))
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
    return text


@given(mutated())
def test_mutations_of_a_valid_program(text):
    check_outcome(text)


def test_the_valid_program_is_valid():
    program = parse(VALID)
    assert len(program.moves) == 8 and program.end is not None


@st.composite
def blocks(draw):
    """Blocks of well-formed words with values chosen to reach the deep checks."""
    words = []
    for _ in range(draw(st.integers(1, 6))):
        letter = draw(st.sampled_from("GGGMXXYYIJRFFPSTN"))
        value = draw(st.one_of(st.sampled_from(INTERESTING),
                               st.floats(-100, 100, allow_nan=False).map(lambda v: round(v, 4))))
        words.append(f"{letter}{value:.6f}".rstrip("0").rstrip("."))
    return " ".join(words)


@given(st.lists(blocks(), min_size=1, max_size=12))
def test_random_blocks_are_all_or_nothing(program):
    interp = Interpreter()
    for number, block in enumerate(program, start=1):
        state, position, blocks_run = interp.state, interp.position, interp.blocks
        try:
            items = interp.execute(block, line=number)
        except GCodeError as error:
            assert error.line == number and 1 <= error.column <= len(block)
            assert (interp.state, interp.position, interp.blocks) == (
                state, position, blocks_run)
            continue
        for item in items:
            if isinstance(item, Move):
                assert item.start == position
                assert math.isfinite(item.length)
                position = item.end
        assert interp.position == position


# ---------------------------------------------------------------- the LinuxCNC language
LANGUAGE_TOKENS = [
    "#1", "#2", "#<a>", "#<_b>", "##1", "#[1+1]", "=", "[", "]", "+", "-", "*", "/", "**",
    " MOD ", " EQ ", " NE ", " LT ", " GT ", " AND ", " OR ", " XOR ", "SIN[", "ATAN[1]/[",
    "SQRT[", "LN[", "EXP[", "ROUND[", "FIX[", "EXISTS[#<a>]", "0", "1", "2", "-1", "0.5",
    "360", "1000000", "X", "Y", "G1 ", "G0 ", "G2 ", "G91 ", "F100 ", "@", "^", "P", "R",
    "\n", "\n", "\n", "o1 while ", "o1 endwhile", "o1 do", "o1 if ", "o1 else", "o1 endif",
    "o2 repeat ", "o2 endrepeat", "o1 break", "o1 continue", "o<s> sub", "o<s> endsub",
    "o<s> call ", "o<s> return ", "o<t> call", "(c)", ";", "%",
]


@settings(suppress_health_check=[HealthCheck.too_slow], max_examples=400, deadline=None)
@given(st.lists(st.sampled_from(LANGUAGE_TOKENS), max_size=60))
def test_language_soup_ends_in_items_or_a_placed_error_quickly(tokens):
    """Random parameters, expressions and O-words: a placed GCodeError or items, never
    another exception, and bounded loops and recursion end quickly."""
    import time

    from twin.controller.gcode import Limits, ReaderOptions

    text = "".join(tokens)
    options = ReaderOptions(limits=Limits(loop_iterations=200, call_depth=20))
    t0 = time.perf_counter()
    try:
        items = parse(text, options=options)
    except GCodeError as error:
        lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        assert 1 <= error.line <= len(lines)
        if error.file is None:
            assert error.source == lines[error.line - 1]
            assert 1 <= error.column <= max(len(error.source), 1)
        assert error.code and error.message
    else:
        for move in items.moves:
            assert all(math.isfinite(v) for v in (*move.start, *move.end))
    assert time.perf_counter() - t0 < 10.0


def _structured(rng, depth: int, labels: list[int], loops: list[str]) -> list[str]:
    """Random well-nested control flow: loops that may or may not end, branches, breaks,
    subroutine calls that may recurse."""
    lines: list[str] = []
    for _ in range(rng.randint(1, 4)):
        kind = rng.choice(["set", "move", "if", "while", "do", "repeat", "call", "jump"])
        if depth == 0 or kind in ("set", "move"):
            lines.append(rng.choice(["#1 = [#1 + 1]", "#2 = [#2 * 2 MOD 7]",
                                     "G1 X[#1 MOD 50] Y[#2]", "G0 X0 Y0"]))
            continue
        labels[0] += 1
        o = f"o{labels[0]}"
        condition = rng.choice(["[#1 LT 5]", "[1]", "[0]", "[#2 NE 3]"])
        if kind == "if":
            lines += [f"{o} if {condition}", *_structured(rng, depth - 1, labels, loops),
                      f"{o} else", *_structured(rng, depth - 1, labels, loops), f"{o} endif"]
        elif kind == "while":
            body = _structured(rng, depth - 1, labels, [*loops, o])
            lines += [f"{o} while {condition}", *body, f"{o} endwhile"]
        elif kind == "do":
            body = _structured(rng, depth - 1, labels, [*loops, o])
            lines += [f"{o} do", *body, f"{o} while {condition}"]
        elif kind == "repeat":
            body = _structured(rng, depth - 1, labels, [*loops, o])
            lines += [f"{o} repeat [{rng.randint(0, 4)}]", *body, f"{o} endrepeat"]
        elif kind == "call":
            lines.append(f"o<s> call [#1] [{rng.randint(0, 3)}]")
        elif loops:
            lines.append(f"{loops[-1]} {rng.choice(['break', 'continue'])}")
    return lines


@settings(suppress_health_check=[HealthCheck.too_slow], max_examples=300, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_random_control_flow_ends_in_items_or_a_bound_quickly(seed):
    import random
    import time

    from twin.controller.gcode import Limits, ReaderOptions

    rng = random.Random(seed)
    labels = [0]
    sub = ["o<s> sub", "o100 if [#2 GT 0]", "o<s> call [#1 + 1] [#2 - 1]", "o100 endif",
           *_structured(rng, 2, labels, []), "o<s> return [#1]", "o<s> endsub"]
    if rng.random() < 0.3:                       # recursion that never ends
        sub[1:4] = ["o<s> call [#1] [#2]"]
    text = "\n".join(["G21 G90 F500 G1", "#1 = 0", "#2 = 0", *sub,
                      *_structured(rng, 3, labels, []), "M2"])
    options = ReaderOptions(limits=Limits(loop_iterations=300, call_depth=30))
    t0 = time.perf_counter()
    try:
        parse(text, options=options)
    except GCodeError as error:
        assert error.code in ("loop-limit", "call-depth", "out-of-range"), (error, text)
    assert time.perf_counter() - t0 < 10.0
