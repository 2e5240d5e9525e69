"""Replays (:mod:`sarmoco.daemon.runner`): recordings played back through the live ingest path.

A simulated run is written as files by ``sarmoco sim --out`` (a ``.vrt`` radar file and
a MAVLink telemetry log), replayed from the files into a store, and that store replayed
twice more. Every replay reads its pulses through ``Pipeline.read_radar`` and offers
its INS samples through ``Pipeline.add_nav``, as a live run does.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.runner import replay_files, replay_store
from sarmoco.store import schema
from sarmoco.store.flags import PushResult
from sarmoco.store.reader import RunStore, open_store
from tests.daemon.same_images import assert_same_images

PULSES = 800
"""Pulses simulated (ku-vehicle at scale 0.05: a few tiles in seconds)."""


@pytest.fixture(scope="module")
def replays(tmp_path_factory: pytest.TempPathFactory) -> tuple[Config, list[RunStore]]:
    """The run replayed from its files (stores[0]), that store replayed (stores[1]), and
    that replay replayed (stores[2])."""
    out = tmp_path_factory.mktemp("replays")
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale", "0.05",
         "--pulses", str(PULSES), "--motion", "turbulence", "--motion-seed", "1",
         "--ins-grade", "tactical", "--out", str(out / "sim")],
        check=True, capture_output=True,
    )  # fmt: skip
    cfg = load_config(out / "sim" / "sarmoco.toml")
    paths = [out / f"replay{k}.zarr" for k in range(3)]
    replay_files(cfg, out / "sim" / "radar.vrt", out / "sim" / "nav.tlog", paths[0], False)
    replay_store(cfg, paths[0], paths[1], progress=False)
    replay_store(cfg, paths[1], paths[2], progress=False)
    return cfg, [open_store(p) for p in paths]


def _accepted_in_time_order(store: RunStore) -> dict[str, np.ndarray]:
    nav = store.read("nav")
    keep = np.flatnonzero(nav["result"] == int(PushResult.ACCEPTED))
    keep = keep[np.argsort(nav["t_ns"][keep], kind="stable")]
    return {k: v[keep] for k, v in nav.items()}


def test_a_replayed_store_gives_the_image_of_its_recording(
    replays: tuple[Config, list[RunStore]],
) -> None:
    _, (files, again, _) = replays
    assert files.committed("pulses") == again.committed("pulses") == PULSES
    assert_same_images(files, again)
    for name in ("t_ns", "pulse_id", "channel", "flags"):
        np.testing.assert_array_equal(
            files.read("pulses", [name])[name], again.read("pulses", [name])[name]
        )


def test_the_replay_is_offered_what_the_recording_accepted(
    replays: tuple[Config, list[RunStore]],
) -> None:
    """The INS samples a replay records are the ones its recording accepted, in time order,
    every field decoded as it was encoded; the replay accepts them all."""
    _, (files, again, _) = replays
    want = _accepted_in_time_order(files)
    got = again.read("nav")
    assert got["t_ns"].size == want["t_ns"].size > 0
    assert (got["result"] == int(PushResult.ACCEPTED)).all()
    for name in ("t_ns", "kind", "vel_ned", "pos_ned", "quat"):
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert again.attrs[schema.INS_RAW_ATTR] == files.attrs[schema.INS_RAW_ATTR]
    assert again.ins_bytes() == files.ins_bytes()


def test_replaying_a_replay_changes_nothing(replays: tuple[Config, list[RunStore]]) -> None:
    """A replay's input is all in its store: replaying it again is bit for bit the same
    (images, motion solution, autofocus estimates, reference track)."""
    cfg, (_, once, twice) = replays
    assert once.n_images == twice.n_images > 0
    for k in range(once.n_images):
        np.testing.assert_array_equal(once.image(k)[0].data, twice.image(k)[0].data)
    tables = ["motion", "nav"] + (["autofocus"] if cfg.autofocus.enabled else [])
    for table in tables:
        a, b = once.read(table), twice.read(table)
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"{table}/{name}")
    ref = schema.REFERENCE_TRACK_ATTR
    assert once.attrs[ref] == twice.attrs[ref]
