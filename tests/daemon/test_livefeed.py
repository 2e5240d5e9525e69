"""The live page's in-memory feed (:mod:`sarmoco.daemon.livefeed`): the recorder hands
its tiles and autofocus estimates over, so the page never opens the store it writes."""

from __future__ import annotations

import io
import shutil
import sys
import threading
from pathlib import Path

import numpy as np
from PIL import Image as PilImage

from sarmoco.daemon.livefeed import LIVE_AUTOFOCUS_ROWS, LIVE_TILES, LiveFeed
from sarmoco.daemon.status import LiveView
from sarmoco.processing.autofocus.report import SubapertureReport
from sarmoco.processing.types import Image
from sarmoco.store import schema
from sarmoco.store.recorder import Recorder


def _tile(k: int, rng: np.random.Generator) -> Image:
    data = (rng.normal(size=(40, 30)) + 1j * rng.normal(size=(40, 30))).astype(np.complex64)
    return Image(data, 10.0 * k + 0.25 * np.arange(40), 900.0 + 0.2 * np.arange(30), "ground")


def _reports(t0_s: float, n: int) -> list[SubapertureReport]:
    return [
        SubapertureReport(
            index=i,
            t_center_s=t0_s + 0.1 * i,
            envelope_lines=None,
            phase_lines=None,
            accel_yz_mps2=(0.01 * i, -0.02 * i),
            accel_residual_hz_per_s=0.0,
            kappa=np.zeros(3),
            kappa_residual_hz_per_s=0.0,
        )
        for i in range(n)
    ]


def test_the_page_is_served_from_memory_with_the_store_gone(tmp_path: Path) -> None:
    """Tiles and autofocus rows recorded by a real recorder reach the page; with the store
    deleted afterwards the page still has all of them (it never reads the store)."""
    path = tmp_path / "run.zarr"
    feed = LiveFeed()
    view = LiveView(path, feed, min_interval_s=0.0)
    rng = np.random.default_rng(3)
    with Recorder(path, 8, "int16", config={}, fsync_interval_s=0.0, live=feed) as rec:
        for k in range(LIVE_TILES + 2):
            rec.add_image(_tile(k, rng), k, k + 1)
        for start in (0.0, 100.0):
            subs = _reports(start, LIVE_AUTOFOCUS_ROWS - 50)
            rec.append_rows(schema.AUTOFOCUS, schema.encode_autofocus(subs))
    shutil.rmtree(path)
    png = view.png()
    assert png is not None
    strip = PilImage.open(io.BytesIO(png))
    assert strip.size == (LIVE_TILES * 40, 30)  # the newest tiles side by side, range up
    live = view.summary()
    assert live["tiles"] == LIVE_TILES + 2
    af = live["autofocus"]
    assert len(af["t_s"]) == len(af["a_y_mps2"]) == len(af["a_z_mps2"]) == LIVE_AUTOFOCUS_ROWS
    newest = _reports(100.0, LIVE_AUTOFOCUS_ROWS - 50)[-1]
    assert af["t_s"][-1] == newest.t_center_s
    assert (af["a_y_mps2"][-1], af["a_z_mps2"][-1]) == newest.accel_yz_mps2
    assert [t.index for t in feed.snapshot().tiles] == list(range(2, LIVE_TILES + 2))


def test_snapshots_taken_while_the_recorder_adds_are_whole() -> None:
    """A reader thread's snapshots, taken while tiles and rows are added, each hold the
    newest tile of their count and columns of one length."""
    feed = LiveFeed()
    rng = np.random.default_rng(4)
    tiles = [_tile(k, rng) for k in range(8)]
    done = threading.Event()
    bad: list[str] = []

    def read() -> None:
        while not done.is_set():
            snap = feed.snapshot()
            lengths = {len(v) for v in snap.autofocus.values()}
            if snap.tiles and snap.tiles[-1].index != snap.n_tiles - 1:
                bad.append(f"newest tile {snap.tiles[-1].index} of {snap.n_tiles}")
            if len(lengths) != 1:
                bad.append(f"column lengths {lengths}")

    reader = threading.Thread(target=read)
    switch_s = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads interleave at nearly every bytecode
    reader.start()
    try:
        for k in range(2000):
            feed.add_tile(k, tiles[k % len(tiles)], k, k + 1)
            feed.add_autofocus(schema.encode_autofocus(_reports(float(k), 3)))
    finally:
        done.set()
        reader.join()
        sys.setswitchinterval(switch_s)
    assert not bad, bad[:3]
    assert feed.snapshot().n_tiles == 2000
