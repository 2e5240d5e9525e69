"""How many pulses a SIGKILL costs the recorder: fewer than a chunk's.

A child process hands blocks of full-size pulses (4096 int16 I/Q samples, chunks of 128
pulses: 2 MiB, written a whole chunk at a time) to a :class:`Recorder`, reports how
many it handed after each call, and is SIGKILLed after a few. The store then holds
every pulse up to the last whole chunk handed (``committed``), at most
``chunk_pulses - 1`` fewer than were handed, each one exactly as written.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

from sarmoco.store.reader import open_store

CHUNK = 128
BLOCKS = (100, 100, 60, 200, 77)
"""Pulses per call: they end inside chunks and on none of their boundaries."""

CHILD = """
import sys
import numpy as np
from sarmoco.store.recorder import Recorder

rec = Recorder(sys.argv[1], 4096, "int16", chunk_pulses={chunk})
n = 0
for k in {blocks}:
    ids = np.arange(n, n + k, dtype=np.int64)
    echo = ((ids[:, None, None] * 31 + np.arange(8192).reshape(4096, 2)) % 4000).astype(np.int16)
    rec.append_pulses(ids * 1000, ids, np.zeros(k, np.int32), np.zeros(k, np.uint32), echo)
    n += k
    print(n, flush=True)
sys.stdin.read()  # wait to be killed
"""


def test_sigkill_loses_fewer_pulses_than_a_chunk(tmp_path: Path) -> None:
    store = tmp_path / "run.zarr"
    code = CHILD.format(chunk=CHUNK, blocks=BLOCKS)
    child = subprocess.Popen(
        [sys.executable, "-c", code, str(store)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert child.stdout is not None
    handed = [int(child.stdout.readline()) for _ in BLOCKS]
    child.send_signal(signal.SIGKILL)
    assert child.wait(30) == -signal.SIGKILL
    assert handed[-1] == sum(BLOCKS)
    committed = open_store(store).committed("pulses")
    assert handed[-1] - CHUNK < committed <= handed[-1]
    assert committed == handed[-1] // CHUNK * CHUNK
    got = open_store(store).read("pulses", ["echo", "pulse_id"])
    ids = np.arange(committed, dtype=np.int64)
    want = ((ids[:, None, None] * 31 + np.arange(8192).reshape(4096, 2)) % 4000).astype(np.int16)
    assert np.array_equal(got["pulse_id"][:committed], ids)
    assert np.array_equal(got["echo"][:committed], want)
