"""Fuzzing the configuration loader: random values in a valid table, and damaged TOML text.

Starting from the default configuration (a table that loads), keys get random values of
any TOML type (huge integers, NaN, infinities, subnormals, strings, arrays, tables),
unknown keys appear and sections are replaced; the TOML text of a valid table is then
damaged character by character. Requirements: :func:`parse_config` and
:func:`load_config` return a :class:`Config` or raise
:class:`~sarmoco.errors.ConfigError` whose message names a key (``section.key``, the
unknown key, or the file); nothing else escapes.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sarmoco.daemon.config import Config, RadarConfig, config_to_dict, load_config, parse_config
from sarmoco.errors import ConfigError
from tests.fuzz.bounds import assert_named_error, bounded_allocation

FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _toml_ready(value: Any) -> Any:
    """``value`` as TOML writes it: tuples as arrays, unset keys (None) left out."""
    if isinstance(value, dict):
        return {k: _toml_ready(v) for k, v in value.items() if v is not None}
    if isinstance(value, tuple | list):
        return [_toml_ready(v) for v in value]
    return value


DEFAULT = _toml_ready(config_to_dict(Config()))
KEYS = [f"{s}.{k}" for s, section in DEFAULT.items() for k in section]
SECTIONS = [f"{s}:" for s in DEFAULT]

scalars = st.one_of(
    st.integers(),
    st.integers(-(2**70), 2**70),
    st.sampled_from([0, -1, 1, 10**400, 2**63, 2**64]),
    st.floats(),
    st.sampled_from([math.nan, math.inf, -math.inf, 5e-324, 1e308, -0.0]),
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(["matched", "dechirp", "up", "int16", "mavlink", "sbg", "none"]),
)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner),
    max_leaves=6,
)


@st.composite
def table(draw: Any) -> tuple[dict[str, Any], set[str]]:
    """The default table with random edits, and the key paths edited."""
    t = {s: dict(sec) for s, sec in DEFAULT.items()}
    edited: set[str] = set()
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["value", "value", "value", "unknown", "section"]))
        if op == "value":
            path = draw(st.sampled_from(KEYS))
            section, key = path.split(".")
            if isinstance(t.get(section), dict):
                t[section][key] = draw(values)
                edited.add(path)
        elif op == "unknown":
            name = draw(st.text(min_size=1, max_size=8))
            section = draw(st.sampled_from([*DEFAULT, None]))
            if section is None:
                t[name] = draw(values)
                edited.add(name)
            elif isinstance(t.get(section), dict):
                t[section][name] = draw(values)
                edited.add(f"{section}.{name}")
        else:
            section = draw(st.sampled_from(list(DEFAULT)))
            t[section] = draw(values)
            edited.add(section)
    return t, edited


@FUZZ
@given(table())
def test_random_values_give_a_config_or_a_named_config_error(case: tuple[dict, set[str]]) -> None:
    t, edited = case
    try:
        with bounded_allocation():
            cfg = parse_config(t)
    except ConfigError as exc:
        assert_named_error(exc, *edited, *KEYS, *SECTIONS, "<root>")
        return
    for f in dataclasses.fields(cfg.radar):  # what loads is usable: finite numbers
        v = getattr(cfg.radar, f.name)
        assert not isinstance(v, float) or math.isfinite(v), (f.name, v)


@st.composite
def damaged_text(draw: Any) -> str:
    """TOML text of a valid (edited) table with characters deleted, inserted or replaced."""
    t, _ = draw(table())
    try:
        text = tomli_w.dumps(t)
    except (TypeError, ValueError):  # tomli_w refuses some values (NaN keys, huge ints...)
        text = tomli_w.dumps(DEFAULT)
    chars = list(text)
    for _ in range(draw(st.integers(0, 5))):
        pos = draw(st.integers(0, max(len(chars) - 1, 0)))
        op = draw(st.sampled_from(["del", "ins", "rep"]))
        new = draw(st.sampled_from(list("[]=\"'.,#\n{}0e-+ ax\\\x00")) | st.characters())
        if op == "del" and chars:
            del chars[pos]
        elif op == "ins":
            chars.insert(pos, new)
        elif chars:
            chars[pos] = new
    return "".join(chars)


@FUZZ
@given(damaged_text())
def test_damaged_toml_text_gives_a_config_or_a_named_config_error(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sarmoco.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            load_config(path)
        except ConfigError as exc:
            assert_named_error(exc, str(path), *KEYS, *SECTIONS, "<root>", *_unknown_names(exc))


def _unknown_names(exc: ConfigError) -> list[str]:
    """The key an 'unknown key' error is about (it names what the file has, not ours)."""
    text = str(exc)
    return [text.split(": unknown key")[0]] if ": unknown key" in text else []


def test_radar_defaults_are_a_valid_start() -> None:
    """The fuzzing starts from a table that loads (else every example would be an error)."""
    assert parse_config(DEFAULT) == Config()
    assert isinstance(Config().radar, RadarConfig)


extreme = st.floats(min_value=5e-324, max_value=1.7e308) | st.sampled_from([5e-324, 1e-300, 1e300])


@FUZZ
@given(
    st.sampled_from(["matched", "dechirp"]), extreme, extreme, extreme, extreme,
    st.integers(1, 2**63 - 1) | st.sampled_from([1, 2, 2**62]), extreme, extreme,
)  # fmt: skip
def test_extreme_radar_and_geometry_numbers(
    receive: str, bw: float, pw: float, fs: float, gate: float, n: int, h: float, r_c: float
) -> None:
    """Every positive finite value the keys accept, together: the geometry check answers
    with a named ConfigError or a Config, never an arithmetic exception."""
    t = {s: dict(sec) for s, sec in DEFAULT.items()}
    t["radar"].update(receive=receive, bandwidth_hz=bw, pulse_width_s=pw, sample_rate_hz=fs,
                      range_gate_delay_s=gate, n_samples=n)  # fmt: skip
    t["geometry"].update(height_m=h, center_slant_range_m=r_c)
    try:
        parse_config(t)
    except ConfigError as exc:
        assert_named_error(exc, *KEYS)


@pytest.mark.parametrize(
    ("edits", "key"),
    [
        ({"radar": {"carrier_hz": 10**400}}, "radar.carrier_hz"),  # OverflowError in float()
        ({"radar": {"n_samples": 10**400}}, "radar.n_samples"),  # OverflowError in (n-1)/fs
        ({"radar": {"prf_hz": math.inf}}, "radar.prf_hz"),  # accepted as > 0
        (
            {"radar": {"receive": "dechirp", "bandwidth_hz": 5e-324, "pulse_width_s": 2.0}},
            "radar.bandwidth_hz / radar.pulse_width_s",  # ZeroDivisionError
        ),
        (
            {
                "radar": {"sample_rate_hz": 5e-324, "range_gate_delay_s": 1.0},  # far = inf
                "geometry": {"height_m": 1.0, "center_slant_range_m": 1.35e154},
            },
            None,  # OverflowError in r_c**2; loads now (the window is unbounded)
        ),
    ],
)
def test_found_by_fuzzing(edits: dict[str, dict[str, Any]], key: str | None) -> None:
    """Regressions: each of these escaped parse_config as an arithmetic exception; now a
    ConfigError naming ``key``, or a Config (``key`` None)."""
    t = {s: dict(sec) for s, sec in DEFAULT.items()}
    for section, values in edits.items():
        t[section].update(values)
    if key is None:
        parse_config(t)
        return
    with pytest.raises(ConfigError) as err:
        parse_config(t)
    assert_named_error(err.value, key)


def test_a_file_that_is_not_utf8(tmp_path: Path) -> None:
    """Regression: a lone surrogate / invalid UTF-8 byte escaped load_config as a
    UnicodeDecodeError."""
    path = tmp_path / "sarmoco.toml"
    path.write_bytes(b"\xed\xa0\x80[radar]\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert_named_error(err.value, str(path))
