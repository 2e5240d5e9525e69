"""What the chunk checksum costs the recorder: raw echoes written with and without CRC-32C.

Run as a script (``python -m bench.bench_checksum``). The recorder appends 8192 pulses of
4096 int16 I/Q samples (128 MiB of echoes, chunks of 256 pulses, no compression, fsync off)
into a store in /tmp, three times each way; the best wall time and the process CPU time of
that run are printed as MB/s and CPU seconds per GB. "without" replaces
:func:`sarmoco.store.schema.chunk_codecs` by the same codecs less the checksum.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

from sarmoco.store import schema
from sarmoco.store.recorder import Recorder

BLOCK = 256
BLOCKS = 32
_WITH_CHECKSUM = schema.chunk_codecs


def _without_checksum(compressor: Any = schema.DEFAULT_COMPRESSOR) -> dict[str, Any]:
    codecs = _WITH_CHECKSUM(compressor)
    return {**codecs, "compressors": codecs["compressors"][:-1]}


def _record(echo: np.ndarray) -> tuple[float, float]:
    """Wall and CPU seconds to record ``BLOCKS`` blocks of ``echo``."""
    folder = Path(tempfile.mkdtemp(dir="/tmp"))
    try:
        with Recorder(folder / "r.zarr", echo.shape[1], "int16", fsync_interval_s=1e9) as rec:
            wall, cpu = time.perf_counter(), time.process_time()
            for k in range(BLOCKS):
                t = np.arange(k * BLOCK, (k + 1) * BLOCK, dtype=np.int64)
                zeros = np.zeros(BLOCK, np.int32)
                rec.append_pulses(t, t, zeros, zeros.astype(np.uint32), echo)
            return time.perf_counter() - wall, time.process_time() - cpu
    finally:
        shutil.rmtree(folder)


def main() -> None:
    """Print the recorder's echo throughput with and without the checksum."""
    echo = np.random.default_rng(0).integers(-3000, 3000, (BLOCK, 4096, 2), dtype=np.int16)
    mb = BLOCKS * echo.nbytes / 1e6
    for label, patch in (("with CRC-32C", None), ("without", _without_checksum)):
        runs = []
        for _ in range(3):
            if patch is None:
                runs.append(_record(echo))
            else:
                with mock.patch.object(schema, "chunk_codecs", patch):
                    runs.append(_record(echo))
        wall, cpu = min(runs)
        print(f"{label}: {mb / wall:.0f} MB/s, {cpu / (mb / 1e3):.2f} CPU s per GB")


if __name__ == "__main__":
    main()
