"""The reader against LinuxCNC's own interpreter, ``rs274``, on the same files.

Random programs of five kinds (CAM output in mm and inch, hand-written, parameterised
with loops and subroutines, unit switches, work offsets) are read by both; every move must
agree: the end point to 1e-6 mm (LinuxCNC's doubles, from its Python binding; the 4
decimals rs274 prints, plus 1 nm, for programs with splines), the feed to 1e-9 relative,
the arc's sense and turns, and the arc centre within the centre correction the reader
states (``twin.controller.gcode.arcs``). Programs LinuxCNC refuses must be refused here, at
the same block.

``rs274`` comes with Debian's ``linuxcnc-uspace``; ``make test-linuxcnc`` installs it and
runs this module. Where it is absent the module is skipped and says why.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from tests.controller.linuxcnc import BINDING, PRINTED, RS274, run_rs274
from twin.controller.gcode import ArcTolerance, Move, ReaderOptions, parse
from twin.errors import GCodeError
from twin.units import INCH, MM

pytestmark = pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 is not installed "
                                "(Debian package linuxcnc-uspace; `make test-linuxcnc` "
                                "installs it and runs these tests)")

FULL = os.environ.get("CI") != "true"
AGREE = 1e-9
"""How close an end point must be to LinuxCNC's double (m): the issue's 1e-6 mm."""
PROGRAMS = 40 if FULL else 10          # per kind


def _num(value: float, places: int) -> str:
    text = f"{value:.{places}f}"
    return "0" if float(text) == 0.0 else text


def cam_program(rng: np.random.Generator, inch: bool) -> str:
    """A CAM post's output: 3 decimals in mm, 4 in inch; arcs whose end points are rounded
    on their own, as posts do."""
    places, scale = (4, 1 / 25.4) if inch else (3, 1.0)
    lines = [f"{'G20' if inch else 'G21'} G90 G17 G94 G40 G49 G80 G64 P{0.01 * scale:.4f}",
             f"F{rng.integers(100, 3000) * scale:.1f}"]
    x = y = 0.0
    for _ in range(60):
        choice = rng.random()
        if choice < 0.15:
            x, y = rng.uniform(-100, 100, 2) * scale
            lines.append(f"G0 X{_num(x, places)} Y{_num(y, places)}")
        elif choice < 0.6:
            x += rng.uniform(-20, 20) * scale
            y += rng.uniform(-20, 20) * scale
            lines.append(f"G1 X{_num(x, places)} Y{_num(y, places)}")
        else:
            radius = rng.uniform(0.5, 50) * scale
            a0 = rng.uniform(0, 2 * math.pi)
            sweep = rng.uniform(0.05, 1.9 * math.pi)
            ccw = rng.random() < 0.5
            cx, cy = x - radius * math.cos(a0), y - radius * math.sin(a0)
            a1 = a0 + (sweep if ccw else -sweep)
            ex, ey = cx + radius * math.cos(a1), cy + radius * math.sin(a1)
            lines.append(f"{'G3' if ccw else 'G2'} X{_num(ex, places)} Y{_num(ey, places)} "
                         f"I{_num(cx - x, places)} J{_num(cy - y, places)}")
            x, y = float(_num(ex, places)), float(_num(ey, places))
        if rng.random() < 0.1:
            lines.append(f"F{rng.integers(100, 3000) * scale:.1f}")
    return "\n".join([*lines, "M2"]) + "\n"


def hand_program(rng: np.random.Generator) -> str:
    """What people type: G91, R arcs, turns, comments, N numbers, lower case, odd spacing."""
    lines = ["(a part by hand)", "N10 g21 g90 f 600"]
    for n in range(30):
        kind = rng.integers(0, 8)
        dx, dy = np.round(rng.uniform(-15, 15, 2), 2)
        if kind == 0:
            lines.append(f"N{20 + 10 * n} G91 G1 X{dx} Y{dy} ; relative")
            lines.append("G90")
        elif kind == 1:
            r = round(math.hypot(dx, dy) / 2 + rng.uniform(0.1, 5), 2)
            sign = "-" if rng.random() < 0.3 else ""
            lines.append(f"G91 G{rng.choice([2, 3])} X{dx} Y{dy} R{sign}{r}")
            lines.append("G90")
        elif kind == 2:
            lines.append(f"G91 G2 X0 Y0 I{dx} J{dy} P{rng.integers(1, 3)} (full turns)")
            lines.append("G90")
        elif kind == 3:
            lines.append(f"g0 x {dx * 3} y {dy * 3}")
        elif kind == 4:
            lines.append(f"G1 X{dx * 2}Y{dy * 2}F{rng.integers(50, 900)}")
        elif kind == 5:
            lines.append(f"G4 P0.{rng.integers(1, 9)} G1 X{dx} Y{dy} (dwell, then move)")
        elif kind == 6:
            lines.append(f"G1 @{abs(dx)} ^{dy * 20:.1f} (polar)")
        else:
            lines.append(f"G91 G1 @{dx / 5} ^{dy:.1f}\nG90")
    return "\n".join([*lines, "M30"]) + "\n"


def parameter_program(rng: np.random.Generator) -> str:
    """Parameters, expressions, functions, loops, conditions and subroutines."""
    sides = int(rng.integers(3, 9))
    radius = float(np.round(rng.uniform(5, 30), 3))
    depth = float(np.round(rng.uniform(0.5, 3), 2))
    return f"""(polygon and spiral, parameterised)
G21 G90 F[{rng.integers(200, 900)} + 0.5]
#<_sides> = {sides}
#<r> = {radius}
#<_depth> = {depth}
o<corner> sub
  (#1 = index, #2 = radius)
  #<a> = [360 / #<_sides> * #1]
  G1 X[#2 * COS[#<a>]] Y[#2 * SIN[#<a>]] F[{rng.integers(200, 900)} / 7 * [1 + #1 / 3]]
o<corner> endsub
G0 X#<r> Y0
#1 = 1
o100 while [#1 LE #<_sides>]
  o<corner> call [#1] [#<r>]
  #1 = [#1 + 1]
o100 endwhile
#2 = 0
o101 do
  #2 = [#2 + 1]
  o102 if [#2 MOD 2 EQ 0]
    G3 X[#<_x> - 2 * #2] Y#<_y> I[-#2] J0 (a half circle from where it is)
  o102 elseif [#2 EQ 3]
    G1 X[ROUND[#<r> * 10] / 10] Y[FIX[#<r>]]
  o102 else
    G1 X[FUP[#<r> / 3]] Y[SQRT[#<r>] ** 2 - ATAN[1]/[1]]
  o102 endif
  o103 if [#2 GT 4 AND #<_depth> GT 0]
    o101 break
  o103 endif
o101 while [#2 LT 10]
o104 repeat [3]
  G91 G1 X[ABS[-1.5]] Y[EXP[0] - LN[1]]
  G90
o104 endrepeat
G1 X[ASIN[0.5] / 10] Y[ACOS[0.5] / 10 + TAN[45]]
G1 X[2 ** 3 ** 2 / 100] Y[-7 MOD 3 + [1 XOR 0] + [2 OR 0] - [0 AND 1]]
M2
"""


def units_program(rng: np.random.Generator) -> str:
    """G20/G21 switches, with F in the same block (F is set before the units)."""
    lines = ["G21 G90 F300"]
    for _ in range(20):
        x, y = np.round(rng.uniform(-2, 2, 2), 4)
        units = rng.choice(["G20", "G21", ""])
        feed = f" F{rng.integers(5, 800)}.5" if rng.random() < 0.6 else ""
        lines.append(f"{units} G1 X{x} Y{y}{feed}".strip())
    return "\n".join([*lines, "M2"]) + "\n"


def offsets_program(rng: np.random.Generator) -> str:
    """Work offsets: G10 L2/L20, G54–G59, G92 and its cancels."""
    ox, oy = np.round(rng.uniform(-20, 20, 2), 3)
    return f"""G21 G90 F500
G10 L2 P1 X{ox} Y{oy}
G10 L2 P2 X{oy} Y{ox}
G1 X1 Y1
G55 G1 X2 Y-1
G92 X0 Y0
G1 X3 Y3
G92.2
G1 X1 Y0
G92.3
G1 X0 Y1
G92.1
G54 G1 X-1 Y-1
G10 L20 P0 X5 Y5
G1 X6 Y5
G0 X0 Y0
G20 G1 X0.1 Y0.2
M2
"""


def cycles_program(rng: np.random.Generator) -> str:
    """Drilling cycles: holes at X/Y, repeated with L in G91, and around a circle by polar
    words (their Z moves are not run here; their XY moves are)."""
    lines = ["G21 G90 G17 F200", "G0 Z5"]
    for _ in range(6):
        g = rng.choice(["G81", "G82 P0.2", "G83 Q1", "G73 Q0.5", "G85", "G89 P0.1"])
        x, y = np.round(rng.uniform(-40, 40, 2), 3)
        lines.append(f"{g} X{x} Y{y} R2 Z-3")
        lines.append(f"X{x + 5} Y{y - 5}")
        if rng.random() < 0.5:
            lines.append(f"G91 {g} X{np.round(rng.uniform(-5, 5), 3)} Y2 R2 Z-3 "
                         f"L{rng.integers(2, 5)}")
            lines.append("G90")
        if rng.random() < 0.5:
            lines.append(f"G91 G81 R2 Z-3 ^{rng.integers(10, 90)} L{rng.integers(2, 7)}")
            lines.append("G90")
        lines.append("G80")
    return "\n".join([*lines, "M2"]) + "\n"


KINDS = {
    "cam-mm": lambda rng: cam_program(rng, inch=False),
    "cam-inch": lambda rng: cam_program(rng, inch=True),
    "hand": hand_program,
    "parameters": parameter_program,
    "units": units_program,
    "offsets": offsets_program,
    "cycles": cycles_program,
}


def _from_spiral(pieces: list[Move], start: tuple[float, float], ref) -> float:
    """Largest distance of our arc pieces from LinuxCNC's path for the same block: the
    spiral around its centre from the start radius to the end radius (m)."""
    cx, cy = ref.center
    r0, r1 = math.dist(start, ref.center), math.dist(ref.end, ref.center)
    a0 = math.atan2(start[1] - cy, start[0] - cx)
    total = sum(abs(p.sweep) for p in pieces)
    worst, done = 0.0, 0.0
    for piece in pieces:
        b0 = math.atan2(piece.start[1] - piece.center[1], piece.start[0] - piece.center[0])
        for t in np.linspace(0.0, 1.0, 65):
            angle = b0 + t * piece.sweep
            x = piece.center[0] + piece.radius * math.cos(angle)
            y = piece.center[1] + piece.radius * math.sin(angle)
            # the spiral's radius at this point's angle around LinuxCNC's centre
            around = math.atan2(y - cy, x - cx)
            turned = ((around - a0) if ref.ccw else (a0 - around)) % (2 * math.pi)
            near = done + t * abs(piece.sweep)
            turned += 2 * math.pi * round((near - turned) / (2 * math.pi))
            f = min(max(turned / total, 0.0), 1.0)
            worst = max(worst, abs(math.hypot(x - cx, y - cy) - (r0 + f * (r1 - r0))))
        done += abs(piece.sweep)
    return worst


def _compare(text: str, path, folder: str | None = None) -> dict[str, float]:
    """Read ``text`` with both; assert agreement; return the largest differences."""
    if folder is None:
        path.write_text(text)
    reference = run_rs274(path)
    if folder is None:
        assert reference.error is not None or reference.precise, \
            "a generated program is compared with LinuxCNC's doubles, not its printout"
    try:
        ours = [item for item in parse(text, options=ReaderOptions(z="ignore"),
                                       folder=folder) if isinstance(item, Move)]
    except GCodeError as error:
        if folder is not None and reference.error is None:
            raise                           # a shipped program: the caller judges it
        assert reference.error is not None, f"we refuse what LinuxCNC runs: {error}"
        assert error.source.strip() == reference.error_block, (error, reference.error)
        return {"refused by both": 1}
    assert reference.error is None, f"LinuxCNC refuses what we run: {reference.error} " \
                                    f"at {reference.error_block}"
    worst = {"end": 0.0, "feed": 0.0}
    worst["end mm" if reference.precise else "end (printed units)"] = worst.pop("end")
    i = 0
    for ref in reference.moves:
        if ref.unsure and i > 0 and math.dist(ours[i - 1].end, ref.end) <= \
                math.sqrt(2) * (PRINTED * ref.unit + 1e-9):
            continue                             # a Z-only move after a spline
        assert i < len(ours), "fewer moves than LinuxCNC"
        move = ours[i]
        pieces_from = i
        i += 1
        if ref.kind == "spline":                # our chords of the same block
            assert move.kind == "line"
            while i < len(ours) and ours[i].line == move.line and ours[i].kind == "line":
                i += 1
            assert abs(move.feed - ref.feed) <= 1e-9 * ref.feed
            continue
        assert move.kind == ref.kind
        # a spiral runs as exact pieces: consume them up to the reference's end point
        tolerance = AGREE if reference.precise else math.sqrt(2) * (PRINTED * ref.unit + 1e-9)
        while move.kind == "arc" and math.dist(move.end, ref.end) > tolerance \
                and i < len(ours) and ours[i].line == move.line and ours[i].kind == "arc":
            move = ours[i]
            i += 1
        off = math.dist(move.end, ref.end)
        if reference.precise:
            worst["end mm"] = max(worst["end mm"], off / MM)
        else:
            worst["end (printed units)"] = max(worst["end (printed units)"], off / ref.unit)
        assert off <= tolerance, (move, ref, off)
        if ref.feed is not None:
            relative = abs(move.feed - ref.feed) / ref.feed
            worst["feed"] = max(worst["feed"], relative)
            assert relative <= 1e-9, (move, ref)
        if ref.kind == "arc":
            assert (move.ccw, move.turns) == (ref.ccw, ref.turns), (move, ref)
            first = ours[pieces_from]
            allowed = ArcTolerance.linuxcnc("inch" if ref.unit == INCH else "mm")
            deviation = _from_spiral(ours[pieces_from:i], first.start, ref)
            bound = 2.5 * allowed.allowed(math.dist(ref.end, ref.center)) + 4 * tolerance
            worst["path"] = max(worst.get("path", 0.0), deviation / MM)
            assert deviation <= bound, (ours[pieces_from:i], ref, deviation, bound)
    assert i == len(ours), f"{len(ours) - i} moves more than LinuxCNC"
    return worst


def test_linuxcncs_python_binding_gives_the_reference_its_full_precision():
    """rs274 prints 4 decimals; the 1e-6 mm comparison needs the interpreter's doubles,
    which the same Debian package ships as the ``gcode`` module of the system python3."""
    assert BINDING is not None, ("linuxcnc-uspace is installed but no python3 imports its "
                                 "`gcode` module (it ships in /usr/lib/python3/dist-packages)")


@pytest.mark.parametrize("kind", list(KINDS))
def test_random_programs_agree_with_linuxcnc(kind, tmp_path):
    rng = np.random.default_rng(abs(hash(kind)) % 2**32)
    worst: dict[str, float] = {}
    for n in range(PROGRAMS):
        found = _compare(KINDS[kind](rng), tmp_path / f"{kind}-{n}.ngc")
        for key, value in found.items():
            worst[key] = max(worst.get(key, 0.0), value)
    print(f"\n{kind}: {PROGRAMS} programs agree; largest differences {worst}")


@pytest.mark.parametrize("inch", [False, True])
def test_no_arc_at_cam_precision_is_refused(inch, tmp_path):
    """10 000 arcs as a CAM post rounds them (3 decimals in mm, 4 in inch): LinuxCNC runs
    the whole program, and so must we."""
    rng = np.random.default_rng(11 + inch)
    places, scale = (4, 1 / 25.4) if inch else (3, 1.0)
    count = 10_000 if FULL else 2_000
    lines = [f"{'G20' if inch else 'G21'} G90 F100"]
    for _ in range(count):
        radius = rng.uniform(0.05, 100) * scale
        a0, sweep = rng.uniform(0, 2 * math.pi), rng.uniform(0.01, 2 * math.pi - 0.01)
        sx, sy = rng.uniform(-50, 50, 2) * scale
        sx, sy = float(_num(sx, places)), float(_num(sy, places))
        cx, cy = sx - radius * math.cos(a0), sy - radius * math.sin(a0)
        ccw = rng.random() < 0.5
        a1 = a0 + (sweep if ccw else -sweep)
        lines.append(f"G0 X{_num(sx, places)} Y{_num(sy, places)}")
        lines.append(f"{'G3' if ccw else 'G2'} X{_num(cx + radius * math.cos(a1), places)} "
                     f"Y{_num(cy + radius * math.sin(a1), places)} "
                     f"I{_num(cx - sx, places)} J{_num(cy - sy, places)}")
    text = "\n".join([*lines, "M2"]) + "\n"
    worst = _compare(text, tmp_path / "arcs.ngc")
    print(f"\n{count} CAM arcs ({'inch' if inch else 'mm'}): all run by both; "
          f"largest differences {worst}")


def test_arcs_off_their_circle_are_refused_where_linuxcnc_refuses_them(tmp_path):
    rng = np.random.default_rng(5)
    agree = {"run by both": 0, "refused by both": 0}
    for n in range(60 if FULL else 20):
        units = "G20" if n % 2 else "G21"
        radius = float(np.round(rng.uniform(0.5, 200), 3))
        off = float(np.round(radius * rng.uniform(0.0, 0.004) + rng.uniform(0, 0.05), 4))
        text = (f"{units} G90 F100\nG0 X{radius} Y0\n"
                f"G3 X{-radius - off:.4f} Y0 I{-radius} J0\nM2\n")
        found = _compare(text, tmp_path / f"off-{n}.ngc")
        agree["refused by both" if "refused by both" in found else "run by both"] += 1
    print(f"\narcs near the tolerance: {agree}")
    assert min(agree.values()) > 0


SHIPPED = ("/usr/share/linuxcnc/ncfiles", "/usr/share/doc/linuxcnc/examples")
FEATURES = ("canned cycles", "cutter radius compensation", "lathe", "modal-state",
            "splines", "spindle-synchronised", "only the XY plane", "G10 L", "probing",
            "tool")
"""What a refusal of a shipped program must name: the LinuxCNC feature it needs."""


def test_linuxcncs_own_programs_run_or_name_the_feature_they_need(tmp_path):
    """Every .ngc LinuxCNC ships that its interpreter runs and that moves no axis but X, Y
    and Z (or defines subroutines and moves nothing): at least two thirds run here with
    ``z = "ignore"``, and those with moves give LinuxCNC's moves; each of the rest is
    refused with one error naming the feature it needs."""
    from pathlib import Path

    files = sorted(p for root in SHIPPED for p in Path(root).rglob("*.ngc"))
    assert files, "linuxcnc-uspace ships its example programs under " + ", ".join(SHIPPED)
    chosen, ran, moved, precise, refused = 0, 0, 0, 0, {}
    for path in files:
        reference = run_rs274(path)
        if reference.error is not None or reference.other_axes:
            continue
        chosen += 1
        text = path.read_text(encoding="utf-8", errors="replace")
        try:
            found = _compare(text, path, folder=str(path.parent))
        except GCodeError as error:
            assert any(word in error.message for word in FEATURES), (path, error)
            refused[path.name] = error.message
            continue
        ran += 1
        moved += bool(reference.moves)
        precise += bool(reference.moves) and reference.precise
        assert "refused by both" not in found
    print(f"\nLinuxCNC's programs it runs moving only X, Y, Z: {chosen}; run here {ran} "
          f"({moved} with moves, all equal to LinuxCNC's, {precise} of them to 1e-6 mm, "
          f"the others to rs274's 4 printed decimals); refused {len(refused)}:")
    for name, message in refused.items():
        print(f"  {name}: {message}")
    assert ran >= 2 * chosen / 3
