"""A recorder writing deterministic content until it is killed (for the SIGKILL test).

Usage: ``python crash_writer.py STORE SEED``. Creates the store, prints
``READY`` and writes rounds of pulses (varying block
sizes), INS samples, raw INS bytes, motion rows, autofocus rows and, every few
rounds, an image tile, until killed (or 30 s pass). Every value is a function
of its row number, so a reader can check any committed row.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import numpy.typing as npt

from sarmoco.processing.autofocus.report import SubapertureReport
from sarmoco.processing.types import Image
from sarmoco.store.recorder import Recorder
from sarmoco.store.schema import AUTOFOCUS, encode_autofocus

N_SAMPLES = 64
IMAGE_EVERY = 5


def echo_rows(ids: npt.NDArray[np.int64]) -> npt.NDArray[np.int16]:
    """Raw int16 I/Q of pulses ``ids``, shape (P, N_SAMPLES, 2)."""
    ramp = np.arange(N_SAMPLES * 2, dtype=np.int64).reshape(N_SAMPLES, 2)
    return ((ids[:, None, None] * 7919 + ramp * 31) % 65536 - 32768).astype(np.int16)


def pulse_rows(ids: npt.NDArray[np.int64]) -> dict[str, npt.NDArray[np.generic]]:
    """Per-pulse columns of pulses ``ids``."""
    return {
        "t_ns": 1_400_000_000_000_000_000 + ids * 1_000_000,
        "pulse_id": ids,
        "channel": (ids % 3).astype(np.int32),
        "flags": (ids % 7).astype(np.uint32),
        "echo": echo_rows(ids),
    }


def motion_rows(ids: npt.NDArray[np.int64]) -> dict[str, npt.NDArray[np.generic]]:
    """Motion solution columns of pulses ``ids``."""
    x = ids.astype(np.float64)
    return {
        "pulse_id": ids,
        "t_ns": 1_400_000_000_000_000_000 + ids * 1_000_000,
        "pos_ned": np.stack([x * 0.03, np.sin(x), -100 + np.cos(x)], axis=-1),
        "vel_ned": np.stack([30 + 0 * x, np.cos(x), -np.sin(x)], axis=-1),
        "quat": np.stack([np.cos(x * 1e-3), np.sin(x * 1e-3), 0 * x, 0 * x], axis=-1),
        "d_los_m": x * 1e-5,
        "phase_rad": x * 1e-3,
        "range_shift_m": x * 1e-6,
    }


def nav_rows(ids: npt.NDArray[np.int64]) -> dict[str, npt.NDArray[np.generic]]:
    """INS sample columns of nav rows ``ids``."""
    x = ids.astype(np.float64)
    return {
        "t_ns": 1_400_000_000_000_000_000 + ids * 5_000_000,
        "rx_ns": ids * 5_000_000 + 3_000_000,
        "kind": (ids % 3).astype(np.uint8),
        "vel_ned": np.stack([30 + x, x, -x], axis=-1),
        "pos_ned": np.stack([x, 2 * x, 3 * x], axis=-1),
        "quat": np.stack([1 + 0 * x, x, x, x], axis=-1),
        "result": (ids % 4).astype(np.int8),
    }


def raw_chunk(k: int) -> bytes:
    """Raw INS bytes of chunk ``k`` (length varies with k)."""
    return bytes((k * 13 + i) % 256 for i in range(17 + k % 50))


def autofocus_rows(ids: npt.NDArray[np.int64]) -> dict[str, npt.NDArray[np.generic]]:
    """Autofocus table columns of subapertures ``ids`` (every column the schema declares)."""
    x = ids.astype(np.float64).tolist()
    reports = [
        SubapertureReport(
            index=j,
            t_center_s=0.5 * v,
            envelope_lines=None,
            phase_lines=None,
            accel_yz_mps2=(0.01 * v, -0.02 * v),
            accel_residual_hz_per_s=0.1 * v,
            kappa=np.array([0.25 * v, 1e-3 * v, 1e-6 * v]),
            kappa_residual_hz_per_s=0.05 * v,
        )
        for j, v in zip(ids.tolist(), x, strict=True)
    ]
    return encode_autofocus(reports)


def image_of(k: int) -> Image:
    """Image tile ``k``."""
    data = (np.arange(24 * 32).reshape(24, 32) + 1j * k).astype(np.complex64)
    axis0 = np.asarray(np.arange(24) * 0.1 + k, dtype=np.float64)
    axis1 = np.asarray(np.arange(32) * 0.2, dtype=np.float64)
    return Image(data, axis0, axis1, "ground")


def block_size(round_k: int) -> int:
    """Pulses written in round ``round_k`` (varies so kills land at every offset)."""
    return 1 + (round_k * 37) % 53


def new_recorder(path: str, seed: int, cls: type[Recorder] = Recorder) -> Recorder:
    """The writer's recorder (small chunks, per-pulse metadata in chunks of 128, rows
    gathered for 20 ms, an fsync every 50 ms) of class ``cls``."""
    return cls(
        path,
        N_SAMPLES,
        "int16",
        config={"seed": seed},
        chunk_pulses=32,
        meta_chunk_pulses=128,
        fsync_interval_s=0.05,
        flush_interval_s=0.02,
        chunk_rows=64,
    )


def main(path: str, seed: int) -> None:
    """Write rounds until killed."""
    rec = new_recorder(path, seed)
    print("READY", flush=True)
    write_rounds(rec, 30.0)
    rec.close()


def write_rounds(rec: Recorder, seconds: float, rounds: int | None = None) -> None:
    """Write rounds of every table into ``rec`` for ``seconds`` or ``rounds`` rounds, whichever
    ends first (``rec`` is not closed)."""
    pulses = nav = chunks = subaps = 0
    t_end = time.monotonic() + seconds
    round_k = 0
    while time.monotonic() < t_end and (rounds is None or round_k < rounds):
        n = block_size(round_k)
        ids = np.arange(pulses, pulses + n, dtype=np.int64)
        rows = pulse_rows(ids)
        rec.append_pulses(
            rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"], rows["echo"]
        )
        rec.append_motion(**motion_rows(ids))
        pulses += n
        nav_ids = np.arange(nav, nav + 4, dtype=np.int64)
        rec.append_nav(**nav_rows(nav_ids))
        nav += 4
        rec.append_ins_bytes(raw_chunk(chunks), rx_ns=chunks)
        chunks += 1
        rec.append_rows(AUTOFOCUS, autofocus_rows(np.array([subaps], dtype=np.int64)))
        subaps += 1
        if round_k % IMAGE_EVERY == 0:
            k = round_k // IMAGE_EVERY
            rec.add_image(image_of(k), k, k + 1, {"entropy": float(k)})
        round_k += 1


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
