"""What a configuration will ask of the machine: the memory of its buffers, its data rate.

A run allocates its large buffers when it starts: the echo ring, the read scratch, the
focus backlog, the blocks the focuser works on, an image tile, the recorder's waiting
chunk. Their sizes follow from a few keys (samples per pulse, PRF, block size, tile and
pixel size, swath, chunk size). :func:`plan` computes each one in bytes from the same
constants the pipeline sizes them with; :func:`check_resources` refuses a configuration
whose buffers do not fit the memory limit (``limits.memory_mib``, or the machine's
memory), or whose echo data rate exceeds ``limits.data_rate_mbps``, naming the keys, the
bytes and the limit, before anything is allocated. The figures are lower bounds: the
processing's own temporaries come on top.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from sarmoco.daemon.array_ingest import READ_PACKETS, RING_PULSES
from sarmoco.daemon.config import Config
from sarmoco.daemon.ingest import READ_BLOCK_PULSES, RING_SECONDS, ring_format
from sarmoco.daemon.pipeline import FOCUS_BACKLOG_S
from sarmoco.drivers.samples import sample_dtype, sample_shape
from sarmoco.errors import ConfigError

PULSE_META_BYTES = 8 + 8 + 4 + 4 + 1
"""Bytes the echo ring keeps per pulse beside its samples (time, id, channel, flags, state)."""
COMPLEX64_BYTES = 8
"""Bytes of one complex64 sample or pixel."""


@dataclass(frozen=True)
class Buffer:
    """One buffer a run allocates.

    Attributes
    ----------
    name : str
        What it is, in words.
    keys : tuple of str
        The configuration keys that size it (the first is the one to change first).
    nbytes : int
        Its size, bytes.
    how : str
        The product that gives ``nbytes`` (for the error message).
    """

    name: str
    keys: tuple[str, ...]
    nbytes: int
    how: str


def echo_bytes_per_pulse(cfg: Config) -> int:
    """Bytes of one pulse's samples as the ring holds them (int16 I/Q or complex64), all
    channels."""
    fmt = ring_format(cfg)
    shape = sample_shape(cfg.radar.n_samples, fmt)
    return math.prod(shape) * sample_dtype(fmt).itemsize * cfg.radar.channels


def data_rate_bytes_s(cfg: Config) -> float:
    """Echo data rate the radar keys imply: PRF times the bytes of a pulse, bytes/s."""
    return cfg.radar.prf_hz * echo_bytes_per_pulse(cfg)


def plan(cfg: Config) -> list[Buffer]:
    """The large buffers of a run of ``cfg``, each with the keys that size it.

    Returns
    -------
    list of Buffer
        Single mode: echo ring, read scratch, focus backlog, focusing block, image tile,
        recorder's waiting chunk and writer queue; array mode: echo ring, read scratch,
        alignment backlog and the recorder's (the pulses held for the DEM grow with the
        run: not counted).
    """
    r, im, rec = cfg.radar, cfg.imaging, cfg.recorder
    pulse = echo_bytes_per_pulse(cfg)
    size = f"{r.n_samples} samples x {pulse // (r.n_samples * r.channels)} B"
    if r.channels > 1:
        size += f" x {r.channels} channels"
    buffers: list[Buffer] = []
    if r.mode == "array":
        backlog = max(math.ceil(FOCUS_BACKLOG_S * r.prf_hz), RING_PULSES)
        buffers += [
            Buffer("echo ring", ("radar.n_samples", "radar.channels"),
                   RING_PULSES * (pulse + PULSE_META_BYTES), f"{RING_PULSES} pulses x {size}"),
            Buffer("read scratch", ("radar.n_samples",), READ_PACKETS * pulse // r.channels,
                   f"{READ_PACKETS} packets x {r.n_samples} samples"),
            Buffer("alignment backlog", ("radar.n_samples", "radar.channels", "radar.prf_hz"),
                   backlog * pulse, f"{backlog} pulses ({FOCUS_BACKLOG_S:g} s) x {size}"),
        ]  # fmt: skip
    else:
        ring = max(1024, math.ceil(RING_SECONDS * r.prf_hz))
        backlog = max(math.ceil(FOCUS_BACKLOG_S * r.prf_hz), 2 * im.block_pulses)
        nx = math.ceil(im.tile_length_m / im.pixel_m)
        ny = math.ceil(im.swath_m / im.pixel_m)
        buffers += [
            Buffer("echo ring", ("radar.n_samples", "radar.prf_hz"),
                   ring * (pulse + PULSE_META_BYTES),
                   f"{ring} pulses (at least {RING_SECONDS:g} s at radar.prf_hz) x {size}"),
            Buffer("read scratch", ("radar.n_samples",), READ_BLOCK_PULSES * pulse,
                   f"{READ_BLOCK_PULSES} pulses x {size}"),
            Buffer("focus backlog", ("radar.n_samples", "radar.prf_hz", "imaging.block_pulses"),
                   backlog * pulse, f"{backlog} pulses ({FOCUS_BACKLOG_S:g} s) x {size}"),
            Buffer("focusing block", ("imaging.block_pulses", "radar.n_samples"),
                   2 * im.block_pulses * r.n_samples * COMPLEX64_BYTES,
                   f"2 x {im.block_pulses} pulses x {r.n_samples} complex64 samples "
                   "(the block and its range compression)"),
            Buffer("image tile", ("imaging.pixel_m", "imaging.tile_length_m", "imaging.swath_m"),
                   nx * ny * COMPLEX64_BYTES, f"{nx} x {ny} complex64 pixels"),
        ]  # fmt: skip
    if rec.raw_echoes:
        buffers.append(
            Buffer("recorder chunk", ("recorder.chunk_pulses", "radar.n_samples"),
                   rec.chunk_pulses * pulse, f"{rec.chunk_pulses} pulses x {size}")
        )  # fmt: skip
    if rec.writer_queue and r.mode != "array":
        buffers.append(
            Buffer("writer queue", ("recorder.writer_queue", "imaging.block_pulses"),
                   rec.writer_queue * im.block_pulses * pulse,
                   f"{rec.writer_queue} blocks x {im.block_pulses} pulses x {size}")
        )  # fmt: skip
    return buffers


def machine_memory_bytes() -> int:
    """Memory this process may use: physical memory, or the cgroup's limit when lower, bytes."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit_file).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total


def memory_limit(cfg: Config) -> tuple[int, str]:
    """The memory limit a run is held to, bytes, and where it comes from (in words)."""
    if cfg.limits.memory_mib:
        return round(cfg.limits.memory_mib * 2**20), "limits.memory_mib"
    return machine_memory_bytes(), "the machine's memory; limits.memory_mib sets another"


def human_bytes(n: float) -> str:
    """``n`` bytes as B, KiB, MiB, GiB or TiB with three significant digits."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


_RATE_KEYS = ("radar.prf_hz", "radar.n_samples", "radar.sample_format", "radar.channels")
"""The keys that set the echo data rate."""


def _values(
    cfg: Config | None, keys: tuple[str, ...], options: Mapping[str, object] | None = None
) -> str:
    """``key = value`` of each key: a configuration key, or ``key value`` of one that
    ``options`` gives (a command-line option, an input file)."""
    parts = []
    for key in keys:
        if options and key in options:
            parts.append(f"{key} {options[key]}")
            continue
        assert cfg is not None, key
        section, name = key.split(".")
        parts.append(f"{key} = {getattr(getattr(cfg, section), name)!r}")
    return ", ".join(parts)


def check_memory(
    buffers: list[Buffer],
    limit_bytes: int,
    where: str,
    copies: int = 1,
    cfg: Config | None = None,
    options: Mapping[str, object] | None = None,
) -> None:
    """Refuse a job whose buffers, ``copies`` times over (one set per worker process), do
    not fit ``limit_bytes``.

    Parameters
    ----------
    buffers : list of Buffer
        What one process of the job allocates.
    limit_bytes : int
        Memory limit, bytes.
    where : str
        Where the limit comes from, in words.
    copies : int
        Processes that each allocate ``buffers`` within the same limit.
    cfg : Config, optional
        Configuration the buffers' keys name.
    options : mapping, optional
        Values of the buffers' keys that are not configuration keys (command-line
        options, input files).

    Raises
    ------
    ConfigError
        Naming the key of the largest buffer and its value, its bytes and the product
        that gives them, the total and the limit.
    """
    each = sum(b.nbytes for b in buffers)
    total = each * copies
    if total <= limit_bytes:
        return
    big = max(buffers, key=lambda b: b.nbytes)
    values = _values(cfg, big.keys, options)
    in_all = f"{total} B ({human_bytes(total)}) in all"
    if copies > 1:
        in_all += f" ({copies} worker processes x {human_bytes(each)})"
    raise ConfigError(
        f"{big.keys[0]}: {values}: the {big.name} takes {big.nbytes} B "
        f"({human_bytes(big.nbytes)}: {big.how}), the job's buffers {in_all}, more than "
        f"the memory limit {limit_bytes} B ({human_bytes(limit_bytes)}, {where})"
    )


def check_resources(cfg: Config, limit_bytes: int | None = None) -> list[Buffer]:
    """Refuse a configuration whose buffers do not fit the memory limit, or whose data
    rate exceeds ``limits.data_rate_mbps``; return its buffers otherwise.

    Parameters
    ----------
    cfg : Config
        The configuration.
    limit_bytes : int, optional
        Memory limit, bytes (default :func:`memory_limit`).

    Raises
    ------
    ConfigError
        Naming the keys of the largest buffer, its bytes and the product that gives them,
        the total and the limit; or the radar keys, the data rate and its limit.
    """
    where = "limits.memory_mib"
    if limit_bytes is None:
        limit_bytes, where = memory_limit(cfg)
    buffers = plan(cfg)
    check_memory(buffers, limit_bytes, where, cfg=cfg)
    rate_limit = cfg.limits.data_rate_mbps * 1e6 / 8
    rate = data_rate_bytes_s(cfg)
    if rate_limit and rate > rate_limit:
        raise ConfigError(
            f"radar.prf_hz: {_values(cfg, _RATE_KEYS)} make {rate * 8e-6:.6g} Mbit/s of "
            f"echoes ({human_bytes(rate)}/s), more than "
            f"limits.data_rate_mbps = {cfg.limits.data_rate_mbps:g}"
        )
    return buffers
