"""Configurations checked against the machine (:mod:`sarmoco.daemon.resources`): the buffers
a run allocates, their bytes against the memory limit, the echo data rate, and values that
make no sense together; refused by ``config check``, ``run`` and ``replay`` before anything
is allocated, naming the key, the bytes and the limit."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
import tomli_w

from sarmoco.daemon.config import config_to_dict, load_config, parse_config
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.resources import check_resources, machine_memory_bytes, plan
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
from sarmoco.errors import ConfigError
from tests.app.test_cli import run_cli


def _config(repo_root: Path, tmp_path: Path, extra: str) -> Path:
    """The shipped configuration with ``extra`` ("SECTION KEY = VALUE" lines) set."""
    table = tomllib.loads((repo_root / "systemd" / "sarmoco.toml").read_text())
    for line in extra.strip().splitlines():
        section, assignment = line.split(" ", 1)
        table.setdefault(section, {}).update(tomllib.loads(assignment))
    path = tmp_path / "c.toml"
    path.write_text(tomli_w.dumps(table))
    return path


@pytest.mark.parametrize("verb", ["config", "replay", "run"])
def test_a_buffer_larger_than_the_machine_is_refused_before_it_is_allocated(
    repo_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], verb: str
) -> None:
    path = _config(repo_root, tmp_path, "radar n_samples = 100000000")
    out = tmp_path / "r.zarr"
    argv = {
        "config": ["config", "check", str(path)],
        "replay": ["replay", "--config", str(path), "--radar", "x.vrt", "--nav", "x.tlog",
                   "--out", str(out)],
        "run": ["run", "--config", str(path), "--store", str(out)],
    }[verb]  # fmt: skip
    status, stdout, err = run_cli(argv, capsys)
    limit = machine_memory_bytes()
    ring = 2000 * (100_000_000 * 4 + 25)  # 4 s at 500 Hz, int16 I/Q
    assert status == 2 and stdout == "", err
    assert err.startswith("sarmoco: error: radar.n_samples: radar.n_samples = 100000000, "), err
    assert f"the echo ring takes {ring} B (" in err
    assert f"more than the memory limit {limit} B (" in err and "the machine's memory" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ("imaging block_pulses = 4000000", "imaging.block_pulses"),
        ("imaging pixel_m = 0.0001", "imaging.pixel_m"),
        ("recorder chunk_pulses = 100000000", "recorder.chunk_pulses"),
        ("recorder writer_queue = 100000", "recorder.writer_queue"),
    ],
)
def test_each_buffer_names_its_own_key(
    repo_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: str, key: str
) -> None:
    status, _, err = run_cli(["config", "check", str(_config(repo_root, tmp_path, extra))], capsys)
    assert status == 2 and err.startswith(f"sarmoco: error: {key}: "), err


def test_the_configured_limits(
    repo_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ok = _config(repo_root, tmp_path, "limits memory_mib = 100.0")
    status, out, _ = run_cli(["config", "check", str(ok)], capsys)
    assert status == 0 and "of 100 MiB (limits.memory_mib)" in out
    assert "echo data rate 65.54 Mbit/s" in out  # 500 Hz x 4096 x 4 B x 8 bit
    small = _config(repo_root, tmp_path, "limits memory_mib = 30.0")
    status, _, err = run_cli(["config", "check", str(small)], capsys)
    assert status == 2 and f"more than the memory limit {30 * 2**20} B (" in err
    assert "limits.memory_mib)" in err
    slow = _config(repo_root, tmp_path, "limits data_rate_mbps = 50.0")
    status, _, err = run_cli(["config", "check", str(slow)], capsys)
    assert status == 2 and err.startswith("sarmoco: error: radar.prf_hz: radar.prf_hz = 500.0")
    assert "65.536 Mbit/s of echoes" in err and "limits.data_rate_mbps = 50" in err


def test_the_plan_is_what_the_pipeline_allocates(repo_root: Path, tmp_path: Path) -> None:
    """The echo ring, read scratch and recorder chunk of :func:`plan` are the bytes the
    pipeline's own arrays hold."""
    cfg = load_config(repo_root / "systemd" / "sarmoco.toml")
    buffers = {b.name: b.nbytes for b in check_resources(cfg)}
    with open_recorder(cfg, tmp_path / "s.zarr") as recorder:
        pipe = Pipeline(cfg, recorder, Counters())
        ring = pipe.ring
        held = sum(
            a.nbytes
            for a in (ring._samples, ring._t_ns, ring._pulse_id, ring._channel, ring._flags,
                      ring._state)
        )  # fmt: skip
        assert buffers["echo ring"] == held
        assert buffers["read scratch"] == pipe.radar._scratch.nbytes
        pipe.finish()
    assert sum(buffers.values()) < machine_memory_bytes()


@pytest.mark.parametrize(
    ("section", "values", "message"),
    [
        ("imaging", {"pixel_m": 30.0},
         "imaging.pixel_m: 30.0 m is larger than imaging.tile_length_m"),
        ("imaging", {"pixel_m": 15.0, "tile_length_m": 40.0, "swath_m": 10.0},
         "imaging.pixel_m: 15.0 m is larger than imaging.swath_m 10.0 m"),
        ("ins", {"rate_hz": 2.0}, "ins.rate_hz: 2.0 Hz gives INS samples 0.5 s apart, longer "
         "than the longest interval a pulse is interpolated across"),
        ("ins", {"rate_hz": 1.8, "bridge_gap_s": 0.6}, "longer than ins.latency_budget_s 0.5 s"),
    ],
)  # fmt: skip
def test_values_that_make_no_sense_together(
    section: str, values: dict[str, float], message: str
) -> None:
    table = config_to_dict(parse_config({}))
    table[section].update(values)
    with pytest.raises(ConfigError, match=re.escape(message)):
        parse_config(table)


def test_plan_follows_the_keys() -> None:
    base = {b.name: b.nbytes for b in plan(parse_config({}))}
    double = {b.name: b.nbytes for b in plan(parse_config({"radar": {"n_samples": 8192}}))}
    assert double["read scratch"] == 2 * base["read scratch"]
    assert double["image tile"] == base["image tile"]
