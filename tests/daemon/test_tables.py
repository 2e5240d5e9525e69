"""The recording path's writes: pulses out of the echo ring a unit at a time, into a real store."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sarmoco.daemon.backlog import FocusBacklog
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.tables import RECORD_PART_WAIT_S, RECORD_UNIT_PULSES, RunTables
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder

PRI_NS = 50_000
"""20 kHz."""


def test_pulses_are_stored_a_unit_at_a_time_and_a_part_once_it_has_waited(
    tmp_path: Path,
) -> None:
    unit, n = RECORD_UNIT_PULSES, 2 * RECORD_UNIT_PULSES + 44
    ring, backlog = EchoRing(1024, 8, "int16"), FocusBacklog(4096)
    block = ring.reserve_block(n)
    assert block is not None
    t = np.arange(1, n + 1) * PRI_NS
    block.samples[...] = np.arange(n)[:, None, None]
    ring.commit_block(block, t, np.arange(n), np.zeros(n, np.int32), np.zeros(n, np.uint32))
    wait_ns = round(RECORD_PART_WAIT_S * 1e9)
    with Recorder(tmp_path / "run.zarr", 8, "int16") as rec:
        tables = RunTables(rec)
        assert tables.store_pulses(ring, backlog, int(t[-1]), skips=True) == 2 * unit
        part_due = int(t[2 * unit]) + wait_ns  # the first pulse of the part, due this long
        assert tables.store_pulses(ring, backlog, part_due - 1, skips=True) == 0
        assert tables.store_pulses(ring, backlog, part_due, skips=True) == n - 2 * unit
        assert len(backlog) == n and len(ring) == 0
    pulses = open_store(tmp_path / "run.zarr").read("pulses", ["t_ns", "echo"])
    assert (pulses["t_ns"] == t).all()
    assert (pulses["echo"][:, 0, 0] == np.arange(n)).all()
