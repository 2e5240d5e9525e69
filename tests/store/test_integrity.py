"""Stores that prove their own integrity: a CRC-32C on every chunk, ``sarmoco verify``, and
replays and reports that skip damaged chunks (counted) and focus the rest.

A simulated run (ku-vehicle x0.05, 800 pulses) is replayed from its files into a store;
a copy of it is damaged as a failing card would: bytes flipped in a chunk of raw echoes
and in an image tile's pixels, a byte flipped in a chunk of pulse flags, and the file of
a chunk of pulse times removed.
"""

from __future__ import annotations

import logging
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.cli import main
from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.runner import replay_files, replay_store
from sarmoco.processing.types import Image
from sarmoco.products.report import write_report
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder
from sarmoco.store.verify import verify_store

PULSES = 800
CHUNK = 256
"""recorder.chunk_pulses of the simulator's configuration (rows per chunk of ``pulses``)."""
DAMAGE = {
    "pulses/echo/c/1/0/0": "flip",  # rows 256 .. 511
    "pulses/flags/c/2": "flip",  # rows 512 .. 767
    "pulses/t_ns/c/3": "remove",  # rows 768 .. 799
    "images/tile_000000/data/c/0/0": "flip",
}
SKIPPED_ROWS = 256 + 256 + 32


@pytest.fixture(scope="module")
def stores(tmp_path_factory: pytest.TempPathFactory) -> tuple[Config, Path, Path]:
    """The configuration, the intact store and its damaged copy."""
    out = tmp_path_factory.mktemp("integrity")
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale", "0.05",
         "--pulses", str(PULSES), "--ins-grade", "tactical", "--out", str(out / "sim")],
        check=True, capture_output=True,
    )  # fmt: skip
    cfg = load_config(out / "sim" / "sarmoco.toml")
    assert cfg.recorder.chunk_pulses == CHUNK
    intact = out / "intact.zarr"
    replay_files(cfg, out / "sim" / "radar.vrt", out / "sim" / "nav.tlog", intact, False)
    damaged = out / "damaged.zarr"
    shutil.copytree(intact, damaged)
    for key, how in DAMAGE.items():
        path = damaged / key
        if how == "remove":
            path.unlink()
            continue
        data = bytearray(path.read_bytes())
        for i in {len(data) // 3, len(data) // 2}:  # a byte or two, as a bad sector would
            data[i] ^= 0x5A
        path.write_bytes(bytes(data))
    return cfg, intact, damaged


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    status = main(argv)
    return status, capsys.readouterr().out


def test_verify_passes_an_intact_store(
    stores: tuple[Config, Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _, intact, _ = stores
    report = verify_store(intact)
    assert report.faults == [] and report.unchecked == []  # every array checksummed
    assert report.chunks > 20
    status, out = _cli(["verify", str(intact)], capsys)
    assert status == 0 and out.strip().endswith(": intact")


def test_verify_names_every_damaged_chunk(
    stores: tuple[Config, Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _, _, damaged = stores
    faults = {(f.array, f.index): f.problem for f in verify_store(damaged).faults}
    assert faults == {
        ("pulses/echo", (1, 0, 0)): "checksum mismatch",
        ("pulses/flags", (2,)): "checksum mismatch",
        ("pulses/t_ns", (3,)): "missing",
        ("images/tile_000000/data", (0, 0)): "checksum mismatch",
    }
    status, out = _cli(["verify", str(damaged)], capsys)
    assert status == 1
    assert f"{damaged}/pulses/echo chunk 1,0,0: checksum mismatch" in out
    assert f"{damaged}/pulses/t_ns chunk 3: missing" in out
    assert out.strip().endswith(": 4 damaged")


def test_replay_skips_damaged_chunks_and_focuses_the_rest(
    stores: tuple[Config, Path, Path], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    cfg, intact, damaged = stores
    with caplog.at_level(logging.WARNING):
        summary = replay_store(cfg, damaged, tmp_path / "again.zarr", progress=False)
    again = open_store(tmp_path / "again.zarr")
    kept = open_store(intact).read("pulses", ["t_ns"])["t_ns"]
    rows = np.r_[0:CHUNK]  # rows 256 .. 799 are in damaged chunks
    np.testing.assert_array_equal(again.read("pulses", ["t_ns"])["t_ns"], kept[rows])
    assert again.committed("pulses") == PULSES - SKIPPED_ROWS
    assert summary.pulses_processed > 0 and again.n_images > 0
    text = caplog.text
    assert f"3 damaged chunks skipped ({SKIPPED_ROWS} rows or tiles)" in text
    assert "pulses/echo chunk 1: checksum mismatch" in text
    assert "pulses/t_ns chunk 3: missing" in text


def test_report_skips_damaged_tiles_and_says_so(
    stores: tuple[Config, Path, Path], tmp_path: Path
) -> None:
    _, intact, damaged = stores
    whole = write_report(intact, tmp_path / "intact")
    summary = write_report(damaged, tmp_path / "damaged")
    skipped = summary.damaged_chunks_skipped
    assert any(k.startswith("images/tile_000000: ") for k in skipped)
    assert summary.image is not None and whole.image is not None
    assert summary.image.shape[0] < whole.image.shape[0]
    assert "DAMAGED " in (tmp_path / "damaged" / "report.txt").read_text()


def test_every_chunk_is_written_even_when_it_holds_only_zeros(tmp_path: Path) -> None:
    """A tile whose edge saw no pulse (zero pixels in whole chunks) and a flags column of
    zeros: their chunks are stored all the same, so a missing one is damage."""
    path = tmp_path / "run.zarr"
    data = np.zeros((1100, 1100), np.complex64)  # chunks of 1024 x 1024
    data[:10, :10] = 1.0  # only chunk (0, 0) holds anything
    axis = np.arange(1100) * 0.1
    with Recorder(path, 64, "int16") as rec:
        rec.add_image(Image(data, axis, axis, "ground"), 0, 1)
        t = np.arange(300, dtype=np.int64)
        zeros = np.zeros(300, np.int32)
        rec.append_pulses(t, t, zeros, zeros.astype(np.uint32), np.zeros((300, 64, 2), np.int16))
    report = verify_store(path)
    assert report.faults == [], report.faults
    assert (path / "images" / "tile_000000" / "data" / "c" / "1" / "1").is_file()
