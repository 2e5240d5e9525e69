"""``sarmoco batch`` (:mod:`sarmoco.app.batch`): a simulated recording reprocessed in blocks
on a real dask.distributed LocalCluster (two worker processes on 127.0.0.1) gives the
single-process replay's store: every tile, its attributes, the run metrics and tables.

The blocks are one tile each, so every tile but the first and last of the strip needs
the overlap (pulses of its neighbours' span within half the beam footprint, and the
neighbour tiles for tile PGA): without it the tiles lose pulses and differ.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest

from sarmoco.app.batch import LOOPBACK, check_batch_memory
from sarmoco.app.cli import main
from sarmoco.app.imaging_stream import SegmentStream
from sarmoco.daemon.config import Config, load_config, parse_config
from sarmoco.daemon.resources import plan
from sarmoco.daemon.runner import replay_files, replay_store
from sarmoco.errors import ConfigError
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.imaging.tiles import TileLayout
from sarmoco.store.reader import RunStore, open_store
from tests.workloads.dask_cluster import separate_cluster

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


@pytest.fixture(scope="module")
def replayed(recorded: tuple[Config, Path]) -> tuple[Path, Path]:
    """The single-process replays: of the files, and of the store that replay wrote."""
    cfg, out = recorded
    sim = out / "sim"
    single_files = out / "single_files.zarr"
    replay_files(cfg, sim / "radar.vrt", sim / "nav.tlog", single_files, progress=False)
    single_store = out / "single_store.zarr"
    replay_store(cfg, single_files, single_store, progress=False)
    return single_files, single_store


def assert_same_store(single: RunStore, batch: RunStore, rtol: float = IMAGE_RTOL) -> None:
    """The batch store holds the single-process replay's products (tiles to ``rtol``)."""
    assert batch.attrs["complete"] is True
    assert batch.n_images == single.n_images >= 8
    for k in range(single.n_images):
        (a, attrs_a), (b, attrs_b) = single.image(k), batch.image(k)
        np.testing.assert_array_equal(a.axis0_m, b.axis0_m)
        np.testing.assert_array_equal(a.axis1_m, b.axis1_m)
        err = np.linalg.norm(a.data - b.data) / np.linalg.norm(a.data)
        assert err <= rtol, f"tile {k}: relative L2 difference {err:.3g}"
        assert attrs_a == attrs_b, k
    assert batch.attrs["metrics"] == single.attrs["metrics"]
    for table in ("pulses", "motion", "autofocus"):
        want, got = single.read(table), batch.read(table)
        assert want.keys() == got.keys()
        for name in want:
            np.testing.assert_array_equal(want[name], got[name], err_msg=f"{table}/{name}")


def test_blocks_on_two_workers_give_the_single_process_replay(
    client: Any,
    recorded: tuple[Config, Path],
    replayed: tuple[Path, Path],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``sarmoco batch --scheduler`` on the cluster, a store and a file pair at once."""
    _, out = recorded
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
    single_files, single_store = replayed
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


def listening_addresses(pids: list[int]) -> set[str]:
    """The addresses that processes and their children listen on (TCP and UDP)."""
    tree = [psutil.Process(pid) for pid in pids]
    tree += [child for proc in list(tree) for child in proc.children(recursive=True)]
    return {
        c.laddr.ip
        for proc in tree
        for c in proc.net_connections("inet")
        if c.status in (psutil.CONN_LISTEN, psutil.CONN_NONE)
    }


def test_a_worker_killed_mid_job_costs_only_its_tasks(
    recorded: tuple[Config, Path], replayed: tuple[Path, Path], tmp_path: Path
) -> None:
    """``sarmoco batch --scheduler`` on a cluster of separate processes (``dask scheduler``,
    two ``dask worker``) on 127.0.0.1: one worker is SIGKILLed while it runs a front end
    (its output store half written); its nanny starts a new worker, the task runs again,
    and both recordings' stores equal the single-process replays bit for bit."""
    from distributed import Client

    _, out = recorded
    sim = out / "sim"
    single_files, single_store = replayed
    batch_out = tmp_path / "batch"
    with separate_cluster(tmp_path, 2) as (address, pids), Client(address) as watcher:
        assert address.startswith(f"tcp://{LOOPBACK}:")
        watcher.wait_for_workers(2, timeout=30)
        assert listening_addresses(pids) == {LOOPBACK}
        batch = subprocess.Popen(
            [sys.executable, "-m", "sarmoco", "batch", "--config", str(sim / "sarmoco.toml"),
             str(single_files), "--radar", str(sim / "radar.vrt"), "--nav", str(sim / "nav.tlog"),
             "--out", str(batch_out), "--scheduler", address, "--tiles-per-block", "4"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        outputs = [batch_out / "single_files.zarr", batch_out / "radar.zarr"]
        deadline = time.monotonic() + 300  # workers load sarmoco on their first task
        while True:  # a worker in a front end that has begun writing its store
            busy = {
                worker: keys
                for worker, keys in watcher.processing().items()
                if any(str(k).startswith("front_end") for k in keys)
            }
            if busy and all(p.exists() for p in outputs):
                break
            assert batch.poll() is None, batch.communicate()
            assert time.monotonic() < deadline, (busy, [p.exists() for p in outputs])
            time.sleep(0.05)
        victim = next(iter(busy))
        os.kill(watcher.run(os.getpid, workers=[victim])[victim], signal.SIGKILL)
        stdout, stderr = batch.communicate(timeout=120)
        assert batch.returncode == 0, stderr
        assert victim not in watcher.scheduler_info()["workers"]
        watcher.wait_for_workers(2, timeout=30)  # the nanny's new worker
    (dashboard,) = [line for line in stderr.splitlines() if line.startswith("dashboard: ")]
    assert f"http://{LOOPBACK}:" in dashboard, dashboard  # served (or to be) on loopback only
    assert "2 recording(s)" in stdout
    assert_same_store(open_store(single_files), open_store(outputs[1]), rtol=0.0)
    assert_same_store(open_store(single_store), open_store(outputs[0]), rtol=0.0)
    assert not list(batch_out.glob("*scratch*"))


def test_batch_refuses_outputs_that_exist(
    recorded: tuple[Config, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A batch never overwrites a store (the one it finds on a retried task is its own)."""
    _, out = recorded
    sim = out / "sim"
    (tmp_path / "o.zarr").mkdir()
    status = main(
        ["batch", "--config", str(sim / "sarmoco.toml"), "--radar", str(sim / "radar.vrt"),
         "--nav", str(sim / "nav.tlog"), "--out", str(tmp_path / "o.zarr"), "--workers", "1"]
    )  # fmt: skip
    assert status == 2 and "never overwrites" in capsys.readouterr().err
    assert (tmp_path / "o.zarr").is_dir()


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


def test_batch_refuses_workers_whose_buffers_do_not_fit_the_memory_limit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each worker process holds a run's buffers (its front end is a replay) and an imaging
    block's tiles; a local cluster's ``--workers`` share the limit (``limits.memory_mib``),
    a cluster started apart is held to it per worker. What does not fit is refused before
    any cluster starts, naming the key of the largest buffer and the limit."""
    cfg_path = tmp_path / "c.toml"
    cfg_path.write_text("[limits]\nmemory_mib = 200.0\n")
    cfg = parse_config({"limits": {"memory_mib": 200.0}})
    run = sum(b.nbytes for b in plan(cfg))
    tile = 200 * 600 * 8  # 20 m x 60 m of 0.1 m complex64 pixels
    each = run + 16 * tile
    assert each < 200 * 2**20 < 2 * each  # one worker fits, two do not
    check_batch_memory(cfg, 16, local_workers=1)
    check_batch_memory(cfg, 16, local_workers=None)
    base = ["batch", "--config", str(cfg_path), "--radar", "r.vrt", "--nav", "n.tlog",
            "--out", str(tmp_path / "o.zarr")]  # fmt: skip
    status = main([*base, "--workers", "2"])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("sarmoco: error: radar.n_samples: "), err
    assert f"the job's buffers {2 * each} B (" in err and "2 worker processes x" in err
    assert f"more than the memory limit {200 * 2**20} B (" in err
    assert "limits.memory_mib; shared by --workers 2)" in err
    status = main([*base, "--workers", "1", "--tiles-per-block", "1000"])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith(
        "sarmoco: error: --tiles-per-block: --tiles-per-block 1000, imaging.pixel_m = 0.1, "
        f"imaging.tile_length_m = 20.0, imaging.swath_m = 60.0: the imaging block takes "
        f"{1000 * tile} B ("
    ), err
    with pytest.raises(ConfigError, match=r"\(200 MiB, limits.memory_mib\)$"):
        check_batch_memory(cfg, 1000, local_workers=None)
    assert not (tmp_path / "o.zarr").exists()


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
