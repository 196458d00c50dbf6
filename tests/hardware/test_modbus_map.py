"""The register map: the documented default, validation naming the field, the request plan
(checked against a brute-force minimum) and the encodings (checked against pymodbus's own
converters and struct)."""

from __future__ import annotations

import copy
import re
import struct
import tomllib
from functools import cache

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymodbus.client import ModbusTcpClient

from twin.config import DacConfig
from twin.errors import ConfigError
from twin.hardware.register_map import (
    DEFAULT_MAP,
    INT16_FULL,
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    _spans,
    check_dacs,
    counter_to_words,
    dac_volts,
    dac_word,
    load_register_map,
    register_map_from_dict,
    volts_to_word,
    word_to_volts,
    words_to_counter,
)
from twin.plant.loop import quantise

TABLES = ("input registers", "holding registers", "discrete inputs", "coils")
DOC = tomllib.loads(DEFAULT_MAP.read_text(encoding="utf-8"))


def _with(path: str, value):
    doc = copy.deepcopy(DOC)
    node = doc
    *parents, leaf = path.split(".")
    for p in parents:
        node = node.setdefault(p, {})
    if value is _DELETE:
        del node[leaf]
    else:
        node[leaf] = value
    return doc


_DELETE = object()


def test_default_map_is_the_documented_layout():
    rmap = load_register_map()
    x, y, m = rmap.axes["x"], rmap.axes["y"], rmap.module
    # The issue: counters at input registers 0-3, X then Y.
    assert (x.encoder, y.encoder) == (0, 2)
    assert (x.tacho, y.tacho, x.dac, y.dac, m.watchdog, m.enable) == (4, 5, 0, 1, 2, 0)
    assert [x.limit_min, x.limit_max, x.home, y.limit_min, y.limit_max, y.home,
            x.drive_ready, y.drive_ready, m.watchdog_tripped] == list(range(9))
    assert m.word_order == "high_first" and m.device_id == 1
    # The comment table at the top of the file documents exactly these addresses.
    documented = {t: set() for t in TABLES}
    for line in DEFAULT_MAP.read_text(encoding="utf-8").splitlines():
        m = re.match(r"#\s+(input registers|holding registers|discrete inputs|coils)\s+"
                     r"([\d\-, ]+?)\s{2}", line)
        if m:
            for part in m.group(2).split(","):
                lo, _, hi = part.strip().partition("-")
                documented[m.group(1)].update(range(int(lo), int(hi or lo) + 1))
    mapped = {t: {a + i for _, a, w in entries for i in range(w)}
              for t, entries in zip(TABLES, rmap.signals(), strict=True)}
    assert documented == mapped
    assert [row[0] for row in rmap.describe()] == sorted(
        (row[0] for row in rmap.describe()), key=TABLES.index)


def test_one_tick_is_three_requests_with_the_default_map():
    rmap = load_register_map()
    assert rmap.input_spans() == [(0, 6)]
    assert rmap.discrete_spans() == [(0, 9)]
    assert rmap.holding_runs() == [(0, ("axes.x.dac", "axes.y.dac", "module.watchdog"))]


@pytest.mark.parametrize(("path", "value", "field", "words"), [
    ("axes.y.tacho", 1, "axes.y.tacho", "already used by axes.x.encoder"),
    ("axes.y.encoder", 4, "axes.y.encoder", "already used by axes.x.tacho"),
    ("axes.y.dac", 2, "module.watchdog", "already used by axes.y.dac"),
    ("module.watchdog_tripped", 3, "module.watchdog_tripped", "used by axes.y.limit_min"),
    ("axes.x.encoder", 65535, "axes.x.encoder", "0 … 65534"),
    ("axes.x.dac", -1, "axes.x.dac", "0 … 65535"),
    ("axes.x.dac", True, "axes.x.dac", "integer"),
    ("axes.x.dac", 1.5, "axes.x.dac", "integer"),
    ("axes.x.encoder", _DELETE, "axes.x.encoder", "missing"),
    ("axes.x.spindle", 9, "axes.x.spindle", "unknown key"),
    ("axes.z", {"encoder": 40, "dac": 40, "limit_min": 40, "limit_max": 41}, "axes",
     "exactly the axes x, y"),
    ("module.word_order", "middle", "module.word_order", "high_first, low_first"),
    ("module.dac_full_scale", 10.0, "module.dac_full_scale", "axes.<axis>.dac.full_scale"),
    ("module.tacho_full_scale", float("inf"), "module.tacho_full_scale", "finite"),
    ("module.device_id", 300, "module.device_id", "0 … 247"),
    ("module.enable", _DELETE, "module.enable", "missing"),
    ("registers", {}, "registers", "unknown key"),
])
def test_validation_names_the_field(path, value, field, words):
    with pytest.raises(ConfigError) as info:
        register_map_from_dict(_with(path, value))
    assert info.value.field == field
    assert words in info.value.message


def test_optional_signals_may_be_left_out():
    doc = copy.deepcopy(DOC)
    for a in ("x", "y"):
        for key in ("tacho", "home", "drive_ready"):
            del doc["axes"][a][key]
    del doc["module"]["watchdog_tripped"]
    rmap = register_map_from_dict(doc)
    assert rmap.input_spans() == [(0, 4)]
    assert rmap.discrete_spans() == [(0, 5)]


def test_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such file") as info:
        load_register_map(tmp_path / "missing.toml")
    assert info.value.field == "register_map"
    bad = tmp_path / "bad.toml"
    bad.write_text("[module\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_register_map(bad)
    good = tmp_path / "good.toml"
    good.write_text(DEFAULT_MAP.read_text(encoding="utf-8").replace("encoder = 2 ",
                                                                    "encoder = 10 "))
    assert load_register_map(good).axes["y"].encoder == 10
    assert load_register_map(good).source == str(good)


def test_holding_runs_never_write_a_gap():
    rmap = register_map_from_dict(_with("module.watchdog", 7))
    assert rmap.holding_runs() == [(0, ("axes.x.dac", "axes.y.dac")), (7, ("module.watchdog",))]


# ----------------------------------------------------------------------- request plan
def _min_reads(entries, limit):
    """Brute force: the fewest reads of at most ``limit`` addresses that cover every signal
    whole (dynamic programming over the signals in address order)."""
    ivs = sorted((a, a + w) for _, a, w in entries)

    @cache
    def best(i):
        if i == len(ivs):
            return 0
        start, out = ivs[i][0], float("inf")
        for j in range(i, len(ivs)):
            end = max(e for _, e in ivs[i:j + 1])
            if end - start > limit:
                break
            out = min(out, 1 + best(j + 1))
        return out

    return best(0)


@given(st.sets(st.integers(0, 600), min_size=1, max_size=30),
       st.sampled_from([MAX_READ_REGISTERS, 7, 2]))
def test_spans_cover_everything_in_the_fewest_reads(starts, limit):
    entries = [(f"s{a}", a, 2 if a % 3 == 0 else 1) for a in sorted(starts)]
    # drop overlapping signals (a map would refuse them)
    clean, end = [], -1
    for e in entries:
        if e[1] > end:
            clean.append(e)
            end = e[1] + e[2] - 1
    spans = _spans(clean, limit)
    for _, a, w in clean:
        assert any(s <= a and a + w <= s + c for s, c in spans)
    assert all(1 <= c <= limit for _, c in spans)
    assert len(spans) == _min_reads(clean, limit)


def test_discrete_inputs_split_only_past_the_modbus_limit():
    doc = _with("module.watchdog_tripped", MAX_READ_BITS + 5)
    spans = register_map_from_dict(doc).discrete_spans()
    assert spans == [(0, 8), (MAX_READ_BITS + 5, 1)]


# ----------------------------------------------------------------------- encodings
@given(st.integers(-(2**40), 2**40), st.sampled_from(["high_first", "low_first"]))
def test_counter_words_match_pymodbus(count, order):
    words = counter_to_words(count, order)
    reference = ModbusTcpClient.convert_to_registers(
        count % 2**32, ModbusTcpClient.DATATYPE.UINT32,
        word_order="big" if order == "high_first" else "little")
    assert list(words) == reference
    assert words_to_counter(*words, order) == count % 2**32


def test_high_first_is_big_endian_abcd():
    assert counter_to_words(0x12345678) == (0x1234, 0x5678)
    hi, lo = struct.unpack(">HH", struct.pack(">I", 0xDEADBEEF))
    assert words_to_counter(hi, lo) == 0xDEADBEEF
    assert words_to_counter(lo, hi, "low_first") == 0xDEADBEEF


@given(st.floats(-12.0, 12.0, allow_nan=False))
def test_volts_round_to_the_nearest_int16_code_and_clip(volts):
    fs = 10.0
    word = volts_to_word(volts, fs)
    (code,) = struct.unpack(">h", struct.pack(">H", word))
    if abs(volts) <= fs:
        assert abs(word_to_volts(word, fs) - volts) <= 0.5 * fs / INT16_FULL + 1e-12
    else:
        assert code == (INT16_FULL if volts > 0 else -INT16_FULL)
    assert -INT16_FULL <= code <= INT16_FULL


@pytest.mark.parametrize(("volts", "word"), [
    (0.0, 0), (10.0, 0x7FFF), (-10.0, 0x8001), (20.0, 0x7FFF), (-20.0, 0x8001),
    (float("inf"), 0x7FFF), (float("-inf"), 0x8001), (float("nan"), 0),
    (10.0 / INT16_FULL, 1), (-10.0 / INT16_FULL, 0xFFFF),
])
def test_volts_table(volts, word):
    assert volts_to_word(volts, 10.0) == word


@pytest.mark.parametrize(("volts", "word"), [
    (0.0, 0), (10.0, 0x7FF0), (-10.0, 0x8000), (20.0, 0x7FF0), (-20.0, 0x8000),
    (float("inf"), 0x7FF0), (float("-inf"), 0x8000), (float("nan"), 0),
    (20.0 / 4096, 0x10), (-20.0 / 4096, 0xFFF0), (0.49 * 20.0 / 4096, 0),
])
def test_a_dac_word_is_the_axis_dacs_code_left_justified(volts, word):
    assert dac_word(volts, 10.0, 12) == word        # 12 bits, ±10 V: LSB 20 V / 4096


@pytest.mark.parametrize(("full_scale", "bits"), [(10.0, 12), (10.0, 16), (5.0, 14), (2.5, 1)])
def test_the_dac_is_quantised_once_the_plants_stage_finds_the_drivers_code(full_scale, bits):
    """The driver quantises to the axis DAC's code; the module hands the plant that code's
    exact level, and the plant's DAC stage (``plant.loop.quantise``) gives what it gives for
    the volts themselves: a second quantisation changes nothing."""
    rng = np.random.default_rng(bits)
    half = 2 ** (bits - 1)
    lsb = full_scale / half
    stage = np.array([[lsb, -half, half - 1, 1.0, 0.0]] * 2)
    direct, relayed = np.zeros(2), np.zeros(2)
    for volts in rng.uniform(-1.2 * full_scale, 1.2 * full_scale, (500, 2)):
        quantise(volts, stage, direct)
        levels = np.array([dac_volts(dac_word(v, full_scale, bits), full_scale, bits)
                           for v in volts])
        quantise(levels, stage, relayed)
        np.testing.assert_array_equal(relayed, direct)
        np.testing.assert_array_equal(levels, direct)


def test_a_dac_wider_than_its_register_is_refused_naming_the_axis():
    with pytest.raises(ConfigError, match=r"axes\.y\.dac\.bits"):
        check_dacs({"x": DacConfig(), "y": DacConfig(bits=18)})


def test_a_map_that_sets_the_dac_full_scale_is_told_where_it_lives():
    doc = tomllib.loads(DEFAULT_MAP.read_text(encoding="utf-8"))
    doc["module"]["dac_full_scale"] = 10.0
    with pytest.raises(ConfigError, match=r"axes\.<axis>\.dac\.full_scale") as info:
        register_map_from_dict(doc)
    assert info.value.field == "module.dac_full_scale"
