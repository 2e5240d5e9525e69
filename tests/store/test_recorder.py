"""The recorder and the store reader, and SIGKILL of a real writer."""

from __future__ import annotations

import dataclasses
import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr

from sarmoco.errors import RecorderError
from sarmoco.processing.types import Image
from sarmoco.store.reader import RunStore, open_store
from sarmoco.store.recorder import Recorder
from sarmoco.store.schema import AUTOFOCUS
from tests.store import crash_writer as cw

WRITER = Path(cw.__file__)


def _check_committed(store: RunStore, upto: dict[str, int] | None = None) -> dict[str, int]:
    """Every committed row equals the generator's; returns the committed counts.

    ``upto`` (rows per table, and ``"images"``): check only the rows below these (the
    counts a power loss must keep), not every row the store says is committed.
    """
    counts = upto or {t: store.committed(t) for t in store.tables()}
    n = counts["pulses"]
    ids = np.arange(n, dtype=np.int64)
    got = store.read("pulses", stop=n)
    for name, want in cw.pulse_rows(ids).items():
        assert got[name].shape[0] == n
        np.testing.assert_array_equal(got[name], want, err_msg=f"pulses/{name}")
    for table, gen in (
        ("motion", cw.motion_rows),
        ("nav", cw.nav_rows),
        ("autofocus", cw.autofocus_rows),
    ):
        if table not in counts:  # killed before its first row
            continue
        rows = store.read(table, stop=counts[table])
        for name, want in gen(np.arange(counts[table], dtype=np.int64)).items():
            np.testing.assert_array_equal(rows[name], want, err_msg=f"{table}/{name}")
    for k in range(counts.get("ins_raw", 0)):
        assert store.ins_bytes(k) == cw.raw_chunk(k)
    for k in range(counts.get("images", store.n_images)):
        image, attrs = store.image(k)
        expected = cw.image_of(k)
        np.testing.assert_array_equal(image.data, expected.data)
        np.testing.assert_array_equal(image.axis0_m, expected.axis0_m)
        assert attrs["metrics"] == {"entropy": float(k)}
    if upto is None:
        assert store.dataset("pulses").sizes["pulse"] == n
    return counts


def test_sigkill_at_random_moments_leaves_committed_rows_intact(tmp_path: Path) -> None:
    """12 real writer processes, recording at once, each SIGKILLed at a random moment."""
    rng = np.random.default_rng(2026)
    t_start = time.monotonic()
    trials = 12
    paths = [tmp_path / f"run{k}.zarr" for k in range(trials)]
    procs = [
        subprocess.Popen(
            [sys.executable, str(WRITER), str(path), str(k)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k, path in enumerate(paths)
    ]
    for proc in procs:
        assert proc.stdout is not None and proc.stderr is not None
        assert proc.stdout.readline().strip() == "READY", proc.stderr.read()
    t_ready = time.monotonic()
    for delay, proc in sorted(
        zip(rng.uniform(0.0, 2.0, trials), procs, strict=True), key=lambda pair: pair[0]
    ):
        time.sleep(max(0.0, t_ready + delay - time.monotonic()))
        os.kill(proc.pid, signal.SIGKILL)
    outcomes: list[tuple[int, dict[str, int]]] = []
    for proc, path in zip(procs, paths, strict=True):
        assert proc.wait(10) == -signal.SIGKILL
        store = open_store(path)
        assert store.attrs["complete"] is False
        counts = _check_committed(store)
        outcomes.append((store.n_images, counts))
    elapsed = time.monotonic() - t_start
    pulses = [counts["pulses"] for _, counts in outcomes]
    print(f"{trials} kills in {elapsed:.1f} s; committed pulses per run: {pulses}")
    distinct = {(n_img, *sorted(counts.items())) for n_img, counts in outcomes}
    assert len(distinct) >= 3  # the kills landed at different points


def test_clean_close_trims_and_xarray_reads_it_directly(tmp_path: Path) -> None:
    path = tmp_path / "run.zarr"
    with Recorder(
        path,
        cw.N_SAMPLES,
        "int16",
        config={"radar": {"prf_hz": 500.0}},
        chunk_pulses=16,
        fsync_interval_s=0.0,
    ) as rec:
        for start, n in ((0, 5), (5, 40), (45, 1)):
            rows = cw.pulse_rows(np.arange(start, start + n, dtype=np.int64))
            rec.append_pulses(
                rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"], rows["echo"]
            )
        rec.append_rows(AUTOFOCUS, cw.autofocus_rows(np.arange(3, dtype=np.int64)))
        rec.add_image(cw.image_of(0), 0, 1, {"entropy": 0.0})
        rec.set_metrics({"pslr_db": -13.1})
    store = open_store(path)
    assert store.attrs["complete"] is True
    assert store.attrs["config"] == {"radar": {"prf_hz": 500.0}}
    assert store.attrs["metrics"] == {"pslr_db": -13.1}
    assert store.attrs["versions"]["zarr"].startswith("3.")
    _check_committed(store)
    ds = xr.open_zarr(path, group="pulses", consolidated=False)
    assert ds.sizes == {"pulse": 46, "sample": cw.N_SAMPLES, "iq": 2}
    assert ds["echo"].dims == ("pulse", "sample", "iq")
    np.testing.assert_array_equal(ds["pulse_id"].values, np.arange(46))
    tile = xr.open_zarr(path, group="images/tile_000000", consolidated=False)
    assert tile["data"].dims == ("axis0", "axis1") and tile["data"].dtype == np.complex64
    image, attrs = store.image(0)
    written: Image = cw.image_of(0)
    np.testing.assert_array_equal(image.data, written.data)
    np.testing.assert_array_equal(image.axis0_m, written.axis0_m)
    np.testing.assert_array_equal(image.axis1_m, written.axis1_m)
    assert image.frame == written.frame
    assert (attrs["t0_ns"], attrs["t1_ns"], attrs["metrics"]) == (0, 1, {"entropy": 0.0})


def test_complex64_echoes_motion_nav_and_raw_bytes(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "c.zarr", 8, "complex64", fsync_interval_s=0.0)
    echo = (np.arange(16).reshape(2, 8) * (1 + 1j)).astype(np.complex64)
    rec.append_pulses([10, 20], [0, 1], [0, 0], [0, 1], echo)
    nan3 = np.full(3, np.nan)
    rec.append_nav(
        [5, 6],
        [0, 1],
        np.array([[30.0, 0, 0], nan3]),
        np.array([nan3, nan3]),
        np.array([[np.nan] * 4, [1, 0, 0, 0]]),
        [0, 3],
        rx_ns=[8, 9],
    )
    rec.append_ins_bytes(b"\xff\x5a\x01", rx_ns=7)
    store = open_store(tmp_path / "c.zarr")
    np.testing.assert_array_equal(store.read("pulses")["echo"], echo)
    nav = store.read("nav")
    assert np.isnan(nav["quat"][0]).all() and nav["result"][1] == 3
    assert store.ins_bytes() == b"\xff\x5a\x01"
    with pytest.raises(RecorderError):
        rec.append_pulses([1], [2], [0], [0], None)
    with pytest.raises(RecorderError):
        rec.append_rows(dataclasses.replace(AUTOFOCUS, name="pulses"), {"x": [1]})
    with pytest.raises(RecorderError):
        Recorder(tmp_path / "c.zarr", 8)
    with pytest.raises(RecorderError):
        open_store(tmp_path / "absent.zarr")
    rec.close()


def test_sync_fsyncs_the_files_written(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "s.zarr", 4, "int16", fsync_interval_s=3600.0)
    rec.append_pulses([1], [1], [0], [0], np.zeros((1, 4, 2), np.int16))
    assert rec.sync() >= 5  # chunks of 5 columns, their metadata, the committed count
    assert rec.sync() == 0
    rec.close()


@pytest.mark.parametrize("compression", ["none", "lz4-bitshuffle"])
@pytest.mark.parametrize("direct", [True, False], ids=["o_direct", "refused"])
def test_large_echo_chunks_round_trip_with_and_without_o_direct(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, compression: str, direct: bool
) -> None:
    """Chunks of raw echoes of a MiB and more are written whole (the rows of a partial chunk
    wait in memory, ``committed`` at the chunk boundary, until it fills or the store
    closes) and go to the disk with O_DIRECT (from an aligned buffer, padded to the
    alignment, then cut to their length), or with a plain write where the file system
    refuses O_DIRECT (EINVAL, as older tmpfs and some network file systems answer; injected
    here): either way the samples read back exactly and every chunk file has the length
    zarr gave it (uncompressed: its bytes and their checksum; compressed: lengths that are
    not whole pages)."""
    if not direct:
        real_open = os.open

        def refusing_open(path: Any, flags: int, *args: Any) -> int:
            if flags & os.O_DIRECT:
                raise OSError(errno.EINVAL, "Invalid argument")
            return real_open(path, flags, *args)

        monkeypatch.setattr(os, "open", refusing_open)
    rng = np.random.default_rng(3)
    echo = rng.integers(-3000, 3000, size=(300, 4096, 2), dtype=np.int16)
    t = np.arange(300, dtype=np.int64) * 50_000
    path = tmp_path / "run.zarr"
    with Recorder(path, 4096, "int16", chunk_pulses=128, echo_compression=compression) as rec:
        for lo, hi, committed in ((0, 128, 128), (128, 200, 128), (200, 300, 256)):
            rows = echo[lo:hi].copy()  # whole and partial chunks (2 MiB each)
            rec.append_pulses(t[lo:hi], t[lo:hi], np.zeros(hi - lo, np.int32),
                              np.zeros(hi - lo, np.uint32), rows)  # fmt: skip
            rows[:] = 0  # the caller reuses its rows (a ring slot)
            # the echoes of a partial chunk wait for it to fill: committed stays behind
            assert rec.pulses.committed == committed
            assert open_store(path).committed("pulses") == committed
        assert rec._store._direct == direct
    assert open_store(path).committed("pulses") == 300
    got = open_store(path).read("pulses", ["echo"])["echo"]
    assert got.tobytes() == echo.tobytes()
    files = sorted(f for f in (path / "pulses" / "echo" / "c").rglob("*") if f.is_file())
    sizes = [f.stat().st_size for f in files]
    assert len(sizes) == 3 and not list(path.rglob("*.partial"))
    if compression == "none":
        assert sizes == [128 * 4096 * 4 + 4] * 3  # the samples, then their CRC-32C
    else:
        assert all(s % 4096 for s in sizes), sizes
