"""Configuration loading: defaults, the example file, and error messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from sarmoco.daemon.config import Config, describe_keys, load_config, parse_config
from sarmoco.errors import ConfigError


def test_example_config_loads(repo_root: Path) -> None:
    cfg = load_config(repo_root / "systemd" / "sarmoco.toml")
    assert cfg.radar.carrier_hz == 15.0e9
    assert cfg.ins.lever_arm_m == (0.10, 0.35, -0.05)
    assert cfg.autofocus.estimator == "map-drift"


def test_empty_table_gives_documented_defaults() -> None:
    cfg = parse_config({})
    assert cfg == Config()
    assert isinstance(cfg.radar.prf_hz, float)


def test_config_is_frozen() -> None:
    cfg = parse_config({})
    with pytest.raises(AttributeError):
        cfg.radar.prf_hz = 1.0  # type: ignore[misc]


def test_int_accepted_for_float_key() -> None:
    cfg = parse_config({"radar": {"prf_hz": 2000}})
    assert cfg.radar.prf_hz == 2000.0 and isinstance(cfg.radar.prf_hz, float)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"radar": {"prf_hz": -3}}, "radar.prf_hz: -3 is not > 0"),
        ({"radar": {"prf_hz": "fast"}}, "radar.prf_hz: 'fast' is not a number"),
        ({"radar": {"n_samples": 4.5}}, "radar.n_samples: 4.5 is not an integer"),
        ({"radar": {"prf": 1}}, "radar.prf: unknown key (allowed: "),
        (
            {"radar": {"receive": "fmcw"}},
            "radar.receive: 'fmcw' is not one of 'matched', 'dechirp'",
        ),
        ({"mocomp": {"order": 3}}, "mocomp.order: 3 is not one of 1, 2"),
        ({"ins": {"lever_arm_m": [1, 2]}}, "ins.lever_arm_m: [1, 2] is not a list of 3 numbers"),
        ({"ins": {"lever_arm_m": [1, 2, "x"]}}, "ins.lever_arm_m[2]: 'x' is not a number"),
        ({"autofocus": {"enabled": 1}}, "autofocus.enabled: 1 is not true or false"),
        ({"autofocus": {"overlap": 1.0}}, "autofocus.overlap: 1.0 is not < 1"),
        ({"status": {"http_port": 70000}}, "status.http_port: 70000 is not <= 65535"),
        ({"radar": 5}, "radar: 5 is not a table"),
        ({"rader": {}}, "rader: unknown key"),
    ],
)
def test_errors_name_key_value_and_rule(table: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(table)
    assert str(info.value).startswith(message)


def test_config_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match=r"radar\.prf_hz"):
        parse_config({"radar": {"prf_hz": 0}})


def test_bad_files(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[radar\nprf_hz = 1\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")


def test_every_key_is_documented() -> None:
    rows = describe_keys()
    assert len(rows) > 30
    for row in rows:
        assert row["doc"], row["key"]
        assert row["default"], row["key"]


def test_readme_documents_every_key(repo_root: Path) -> None:
    readme = (repo_root / "README.md").read_text()
    missing = [r["key"] for r in describe_keys() if f"`{r['key']}`" not in readme]
    assert not missing, f"README lacks config keys: {missing}"
