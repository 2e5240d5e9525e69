"""``sarmoco batch`` (:mod:`sarmoco.app.batch`): a simulated recording reprocessed in blocks
on a real dask.distributed LocalCluster (two worker processes on 127.0.0.1) gives the
single-process replay's store: every tile, its attributes, the run metrics and tables.

The blocks are one tile each, so every tile but the first and last of the strip needs
the overlap (pulses of its neighbours' span within half the beam footprint, and the
neighbour tiles for tile PGA): without it the tiles lose pulses and differ.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest

from sarmoco.app.batch import LOOPBACK
from sarmoco.app.cli import main
from sarmoco.app.imaging_stream import SegmentStream
from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.runner import replay_files, replay_store
from sarmoco.daemon.store import RunStore, open_store
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.imaging.tiles import TileLayout

PULSES = 700
"""Pulses simulated (ku-vehicle at scale 0.05: ten tiles)."""

IMAGE_RTOL = 1e-6
"""Largest relative L2 difference of a tile allowed: float32 rounding. A block replays the
same imager calls in the same order as the single-process replay, so the tiles come out
bit-equal here; summation order in another build of the kernel may differ at ~1e-7."""


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """A real local cluster: 2 worker processes, 1 thread each, no dashboard, loopback."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            dashboard_address=None,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Config, Path]:
    """A simulated run as files (radar.vrt + nav.tlog) and its configuration."""
    out = tmp_path_factory.mktemp("batch")
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale", "0.05",
         "--pulses", str(PULSES), "--motion", "turbulence", "--motion-seed", "3",
         "--ins-grade", "tactical", "--out", str(out / "sim")],
        check=True, capture_output=True,
    )  # fmt: skip
    return load_config(out / "sim" / "sarmoco.toml"), out


def assert_same_store(single: RunStore, batch: RunStore) -> None:
    """The batch store holds the single-process replay's products."""
    assert batch.attrs["complete"] is True
    assert batch.n_images == single.n_images >= 8
    for k in range(single.n_images):
        (a, attrs_a), (b, attrs_b) = single.image(k), batch.image(k)
        np.testing.assert_array_equal(a.axis0_m, b.axis0_m)
        np.testing.assert_array_equal(a.axis1_m, b.axis1_m)
        err = np.linalg.norm(a.data - b.data) / np.linalg.norm(a.data)
        assert err <= IMAGE_RTOL, f"tile {k}: relative L2 difference {err:.3g}"
        assert attrs_a == attrs_b, k
    assert batch.attrs["metrics"] == single.attrs["metrics"]
    for table in ("pulses", "motion", "autofocus"):
        want, got = single.read(table), batch.read(table)
        assert want.keys() == got.keys()
        for name in want:
            np.testing.assert_array_equal(want[name], got[name], err_msg=f"{table}/{name}")


def test_blocks_on_two_workers_give_the_single_process_replay(
    client: Any, recorded: tuple[Config, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """``sarmoco batch --scheduler`` on the cluster, a store and a file pair at once."""
    cfg, out = recorded
    assert client.scheduler.address.startswith(f"tcp://{LOOPBACK}:")
    workers = client.scheduler_info()["workers"]
    assert len(workers) == 2 and all(a.startswith(f"tcp://{LOOPBACK}:") for a in workers)
    pids = {os.getpid(), *client.run(os.getpid).values()}  # scheduler, nannies; workers
    assert len(pids) == 3
    listening = {
        (pid, c.laddr.ip)
        for pid in pids
        for c in psutil.Process(pid).net_connections("inet")
        if c.status == psutil.CONN_LISTEN
    }
    assert listening and {ip for _, ip in listening} == {LOOPBACK}, listening
    sim = out / "sim"
    single_files = out / "single_files.zarr"
    replay_files(cfg, sim / "radar.vrt", sim / "nav.tlog", single_files, progress=False)
    single_store = out / "single_store.zarr"
    replay_store(cfg, single_files, single_store, progress=False)

    status = main(
        ["batch", "--config", str(sim / "sarmoco.toml"), str(single_files),
         "--radar", str(sim / "radar.vrt"), "--nav", str(sim / "nav.tlog"),
         "--out", str(out / "batch"), "--scheduler", client.scheduler.address,
         "--tiles-per-block", "1"]
    )  # fmt: skip
    printed = capsys.readouterr()
    assert status == 0
    n, metrics = open_store(single_files).n_images, open_store(single_files).attrs["metrics"]
    focused = metrics["pulses_processed"]
    assert f"single_files.zarr: {focused} pulses focused, {n} tiles" in printed.out
    assert "dashboard:" in printed.err and f"] {2 + n * 2}/{2 + n * 2} tasks" in printed.err
    assert_same_store(open_store(single_files), open_store(out / "batch" / "radar.zarr"))
    assert_same_store(open_store(single_store), open_store(out / "batch" / "single_files.zarr"))
    assert not list((out / "batch").glob("*scratch*"))


def test_batch_command_refuses_what_it_cannot_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Errors name what is wrong, before any cluster is started."""
    cfg = tmp_path / "c.toml"
    cfg.write_text("")
    for argv, words in (
        ([], "give recordings"),
        (["--radar", "r.vrt"], "both --radar"),
        (["--tiles-per-block", "0", "--radar", "r.vrt", "--nav", "n.tlog"], "--tiles-per-block"),
        (["--workers", "0", "--radar", "r.vrt", "--nav", "n.tlog"], "--workers"),
    ):
        status = main(["batch", "--config", str(cfg), "--out", str(tmp_path / "o.zarr"), *argv])
        err = capsys.readouterr().err
        assert status == 2 and words in err, (argv, err)


def test_a_block_gets_the_calls_that_reach_it_and_the_one_that_opens_its_tiles() -> None:
    """:meth:`SegmentStream.calls_within` on calls whose pulses' footprints span 10 m each,
    with a gap: the calls with a footprint in the span, and after the gap the first call
    beyond it (it opens the span's tiles in the single-process replay: the tiles' start
    time comes from it)."""
    layout = TileLayout(100.0, 894.0, 16.5, 10.0, 0.1, 0.05)
    x_m = np.array([[0.0, 9.0], [10.0, 19.0], [20.0, 29.0], [200.0, 209.0]])
    stream = SegmentStream(
        "unused", ReferenceTrack.from_velocity(np.zeros(3), np.array([1.0, 0, 0]), 0),
        layout, np.array([0, 10, 20, 30, 40]), x_m, False,
    )  # fmt: skip
    assert stream.tiles == range(0, 21)
    assert stream.calls_within(25.0, 40.0) == range(2, 3)
    assert stream.calls_within(5.0, 15.0) == range(0, 2)
    assert stream.calls_within(50.0, 60.0) == range(3, 4)
    assert stream.calls_within(300.0, 310.0) == range(4, 4)
