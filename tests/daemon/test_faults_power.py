"""Power loss and SIGKILL during writes: what a recording keeps (the recorder of ``sarmoco run``).

- **Power loss**: a recorder writing every table (``crash_writer``'s deterministic rows)
  copies its store right after each of its fsyncs (a subclass hooking
  :meth:`~sarmoco.store.recorder.Recorder.sync`: zarr and the file system are real).
  A copy is what survives a power cut at that moment for files that were fsynced. The
  damage a cut leaves on top of it: every file written after that fsync is, each on its
  own and in no order, either still the fsynced version (or absent) or already the
  next one (zarr renames each file into place, so no file is torn), and zarr's
  half-written ``.partial`` temporaries lie around with random bytes. The store must
  open and every row below the ``committed`` counts of that fsync must read back intact.
- **SIGKILL at 60 random moments**: one process imports the recorder once and forks a
  writer per trial, killing each at a uniformly random moment of the second after its
  first commit; every store opens with every committed row intact.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder
from tests.store import crash_writer as cw
from tests.store.test_recorder import _check_committed

KILLS = 60
CUTS = 20
"""Power cuts, after fsyncs spread over the run."""
KILL_WINDOW_S = 1.0


class SnapshotRecorder(Recorder):
    """A recorder that copies its store right after each fsync (the hook of this test)."""

    snapshot_root: Path
    writer_queue = 0
    """The recorder's writer thread (its queue depth; 0: the caller's thread writes)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.snapshots: list[Path] = []
        # chunks of 8 rows: the arrays grow (metadata rewritten) every 128 rows
        extra = {"chunk_pulses": 8, "chunk_rows": 8, "writer_queue": self.writer_queue}
        super().__init__(*args, **(kwargs | extra))

    def sync(self) -> int:
        n = super().sync()
        dst = self.snapshot_root / f"{len(self.snapshots):04d}"
        shutil.copytree(self.path, dst)
        self.snapshots.append(dst)
        return n


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in root.rglob("*") if p.is_file()}


def _counts(store: Path) -> dict[str, int]:
    """The committed rows of every table, and the committed images, of a store."""
    s = open_store(store)
    return {t: s.committed(t) for t in s.tables()} | {"images": s.n_images}


def power_cut(synced: Path, later: Path, out: Path, rng: np.random.Generator) -> int:
    """The store a power cut leaves after fsync ``synced`` while ``later`` was being written.

    Returns the number of files taken from ``later``.
    """
    shutil.copytree(synced, out)
    old, new = _files(synced), _files(later)
    taken = 0
    for name, data in new.items():
        if old.get(name) != data and rng.random() < 0.5:
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            (out / name).write_bytes(data)
            taken += 1
    for name in rng.choice(sorted(new), size=3):
        partial = out / f"{name}.{rng.integers(1 << 60):x}.partial"
        partial.parent.mkdir(parents=True, exist_ok=True)
        partial.write_bytes(rng.bytes(int(rng.integers(0, 4096))))
    return taken


@pytest.mark.parametrize("writer_queue", [0, 4], ids=["caller-writes", "writer-thread"])
def test_power_loss_keeps_every_row_below_the_last_fsynced_commit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, writer_queue: int
) -> None:
    snaps = tmp_path / "snapshots"
    snaps.mkdir()
    monkeypatch.setattr(SnapshotRecorder, "snapshot_root", snaps, raising=False)
    monkeypatch.setattr(SnapshotRecorder, "writer_queue", writer_queue)
    rec = cw.new_recorder(str(tmp_path / "run.zarr"), 0, SnapshotRecorder)
    assert isinstance(rec, SnapshotRecorder)
    cw.write_rounds(rec, 60.0, rounds=12)  # 334 pulses, 3 tiles
    rec.close()  # the last snapshot is the closed store
    assert len(rec.snapshots) >= 5, len(rec.snapshots)
    rng = np.random.default_rng(2026)
    cuts = taken = 0
    pairs = list(zip(rec.snapshots, rec.snapshots[1:], strict=False))
    for k in np.unique(np.linspace(0, len(pairs) - 1, CUTS).round().astype(int)):
        synced, later = pairs[k]
        want = _counts(synced)
        out = tmp_path / f"cut{k}.zarr"
        taken += power_cut(synced, later, out, rng)
        store = open_store(out)
        assert all(store.committed(t) >= want.get(t, 0) for t in store.tables()), k
        _check_committed(store, want)
        shutil.rmtree(out)
        cuts += 1
    final = _counts(rec.snapshots[-1])
    print(f"{cuts} power cuts after {len(rec.snapshots)} fsyncs ({taken} later files kept); "
          f"last fsync: {final['pulses']} pulses, {final['images']} tiles")  # fmt: skip
    assert final["pulses"] == 334 and final["images"] == 3  # the pulse arrays grew twice


KILLER = """
import os, signal, sys, time
from pathlib import Path
import numpy as np
from sarmoco.app.benchcmd import committed_now
from tests.store import crash_writer as cw
root, n, window = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rng = np.random.default_rng(12)
for k in range(n):
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the writer: its own zarr event loop, killed while writing
        os.close(r)
        try:
            rec = cw.new_recorder(f"{root}/run{k}.zarr", k)
            os.write(w, b"R")
            cw.write_rounds(rec, 30.0)
        finally:
            os._exit(3)
    os.close(w)
    assert os.read(r, 1) == b"R"
    while committed_now(Path(f"{root}/run{k}.zarr")) == 0:  # writing has begun
        time.sleep(0.005)
    time.sleep(rng.uniform(0.0, window))
    os.kill(pid, signal.SIGKILL)
    assert os.waitpid(pid, 0)[1] == signal.SIGKILL
    os.close(r)
print("KILLED", n)
"""


@pytest.mark.bench  # the longer marked run (57 s); the suite kills 12 daemons elsewhere
def test_sigkill_at_60_random_moments_keeps_committed_rows(tmp_path: Path) -> None:
    t0 = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-c", KILLER, str(tmp_path), str(KILLS), str(KILL_WINDOW_S)],
        capture_output=True, text=True, timeout=300, cwd=Path(cw.__file__).parents[2],
    )  # fmt: skip
    assert done.stdout.strip() == f"KILLED {KILLS}", done.stderr[-3000:]
    pulses = []
    for k in range(KILLS):
        store = open_store(tmp_path / f"run{k}.zarr")
        assert store.attrs["complete"] is False
        pulses.append(_check_committed(store)["pulses"])
    elapsed = time.monotonic() - t0
    print(f"{KILLS} SIGKILLs in {elapsed:.1f} s; committed pulses min {min(pulses)}, "
          f"median {int(np.median(pulses))}, max {max(pulses)}")  # fmt: skip
    assert min(pulses) > 0 and len(set(pulses)) >= 3  # kills while writing, at various points
