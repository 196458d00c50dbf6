"""JSON and TOML nested to random depths up to 100 000 are read, or refused in one
``ConfigError`` naming the place, never a ``RecursionError`` (issue 33). The reference for
the depth is the document Python's own parser builds (where it can build it)."""

from __future__ import annotations

import json
import os
import random
import tomllib

import pytest

from twin.config.loader import read_toml, toml_document
from twin.errors import ConfigError
from twin.nesting import MAX_DEPTH, json_too_deep, toml_too_deep
from twin.system.jsonio import load_json

CI = bool(os.environ.get("CI"))
DECOYS = ['"[[[{{"', '"a\\"[["', '"]]}}"', '"# [ . {"']


def _depth(node) -> int:
    """Levels of lists and dicts below the root (the reference)."""
    if isinstance(node, dict):
        return max((1 + _depth(v) for v in node.values()), default=1)
    if isinstance(node, list):
        return max((1 + _depth(v) for v in node), default=1)
    return 0


def _depths(rng: random.Random, n: int) -> list[int]:
    return [MAX_DEPTH - 1, MAX_DEPTH, MAX_DEPTH + 1,
            *(min(int(10 ** rng.uniform(0, 5)), 100_000) for _ in range(n))]


def _json(rng: random.Random, depth: int) -> tuple[str, int]:
    """A JSON text whose deepest value sits ``depth`` arrays and objects down, with decoy
    brackets in strings beside it; and the offset of the opener that is number
    ``MAX_DEPTH + 1`` (or -1)."""
    opens, closes, at, text = [], [], -1, ""
    for k in range(depth):
        if rng.random() < 0.5:
            piece, close = f"[{rng.choice(DECOYS)}, ", "]"
        else:
            piece, close = f'{{"k{k}": {rng.choice(DECOYS)}, "v": ', "}"
        if k == MAX_DEPTH:
            at = len(text)
        text += piece + ("\n" if rng.random() < 0.1 else "")
        opens.append(piece)
        closes.append(close)
    return text + "1" + "".join(reversed(closes)), at


@pytest.mark.timeout(120)
def test_json_nested_to_random_depths(tmp_path):
    rng = random.Random("json")
    for depth in _depths(rng, 6 if CI else 40):
        text, at = _json(rng, depth)
        if depth <= MAX_DEPTH:
            doc = load_json(text, "x.json")
            assert doc == json.loads(text) and _depth(doc) == depth
            assert json_too_deep(text) is None
            continue
        with pytest.raises(ConfigError) as info:
            load_json(text, "x.json")
        line = text.count("\n", 0, at) + 1
        column = at - (text.rfind("\n", 0, at) + 1) + 1
        assert info.value.field == "x.json"
        assert info.value.message.startswith(f"line {line}, column {column}: nested deeper "
                                             f"than {MAX_DEPTH} levels")
        if depth < 300:                    # where Python's parser can build it: the reference
            assert _depth(json.loads(text)) == depth


def _toml(rng: random.Random, depth: int) -> tuple[str, int]:
    """A TOML text whose deepest value sits ``depth`` levels down (the root not counted),
    made of a header of dotted parts, a dotted key and arrays and inline tables, with decoys
    in strings and comments; how many levels each part takes is random. Returns the text and
    the line where the nesting passes ``MAX_DEPTH``."""
    header = rng.randint(0, min(depth, 3 if rng.random() < 0.7 else depth))
    key = rng.randint(0, min(depth - header, 3 if rng.random() < 0.7 else depth - header))
    rest = depth - header - key
    lines = [f"# a comment [[{{ . {rng.choice(DECOYS)}", f"top = {rng.choice(DECOYS)}"]
    if header:
        array = header >= 2 and rng.random() < 0.3            # [[a.b]]: the array is a level
        parts = ".".join(f"t{k}" for k in range(header - array))
        lines.append(f"[[{parts}]]" if array else f"[{parts}]")
        lines.append(f'"q.[{{" = {rng.choice(DECOYS)}   # [ . ]')
    past = len(lines) - 1 if header > MAX_DEPTH else len(lines) + 1
    value = "1"
    for k in range(rest):
        if rng.random() < 0.5:
            value = f"[{rng.choice(DECOYS)}, {value}]"
        else:
            value = f'{{ "d.{k}" = {rng.choice(DECOYS)}, e{k} = {value} }}'
    name = ".".join(["leaf", *(f"k{k}" for k in range(key))])
    lines.append(f"{name} = {value}")
    return "\n".join(lines) + "\n", past


@pytest.mark.timeout(120)
def test_toml_nested_to_random_depths(tmp_path):
    rng = random.Random("toml")
    path = tmp_path / "m.toml"
    for depth in _depths(rng, 6 if CI else 40):
        text, past = _toml(rng, depth)
        if depth <= 300:              # where tomllib can build it: the reference
            assert _depth(tomllib.loads(text)) - 1 == depth, text[:300]
        if depth <= MAX_DEPTH:
            assert toml_too_deep(text) is None
            assert toml_document(text, "m.toml") == tomllib.loads(text)
            continue
        path.write_text(text)
        with pytest.raises(ConfigError) as info:
            read_toml(path)
        assert info.value.field == str(path)
        assert info.value.message.startswith(f"line {past}, "), info.value.message[:200]
        assert f"nested deeper than {MAX_DEPTH} levels" in info.value.message
        assert len(str(info.value)) < 400        # the table and key are shortened


@pytest.mark.parametrize("text", [
    "a = '''[[[[\n]]]]'''\nb = \"\"\"{{{\\\"\"\"\"\n",     # multi-line strings
    "a = [  # [[[[\n  1,\n]\n",                          # a comment in an array
    "'x.y.z' = 1\n\"p.q\".r = 2\n",                     # quoted keys
    "d = 1979-05-27T07:32:00.999\nf = [1.5, 2.5e3]\n",  # dots in values
])
def test_what_is_not_nesting_is_not_counted(text):
    assert toml_too_deep(text, 2) is None
    assert _depth(tomllib.loads(text)) <= 2
