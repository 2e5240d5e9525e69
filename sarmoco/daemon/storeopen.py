"""A run's store opened as the configuration says, and the format of its raw INS bytes named."""

from __future__ import annotations

from pathlib import Path

from sarmoco.daemon.config import Config, config_to_dict
from sarmoco.daemon.ingest import ring_format
from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.drivers.source import Source
from sarmoco.store.recorder import Recorder, meta_chunk_pulses


def open_recorder(cfg: Config, path: Path, live: LiveFeed | None = None) -> Recorder:
    """The run's recorder, configured from ``recorder.*`` (handing tiles and autofocus
    estimates to ``live``, the live page's feed, if given)."""
    return Recorder(
        path,
        cfg.radar.n_samples,
        ring_format(cfg),
        config=config_to_dict(cfg),
        raw_echoes=cfg.recorder.raw_echoes,
        chunk_pulses=cfg.recorder.chunk_pulses,
        echo_compression=cfg.recorder.echo_compression,
        fsync_interval_s=cfg.recorder.fsync_interval_s,
        flush_interval_s=cfg.recorder.flush_interval_s,
        meta_chunk_pulses=meta_chunk_pulses(cfg.recorder.chunk_pulses, cfg.radar.prf_hz),
        live=live,
        writer_queue=cfg.recorder.writer_queue,
    )


def record_ins_format(recorder: Recorder, ins: Source) -> None:
    """Name the format of the store's raw INS bytes (``ins_raw`` attribute) if it keeps any.

    ``ins_bytes`` then holds what the driver received, back to back, in that format:
    ``tlog`` (MAVLink: a telemetry log), ``sbgecom`` (SBG: the bytes as read),
    ``candump`` (SBG CAN: a ``candump -L`` log); written to a file with the suffix
    ``.tlog``, ``.sbg`` or ``.log`` it is an INS log the daemon reads again.
    """
    if ins.keeping_raw:
        recorder.set_attribute("ins_raw", {"format": ins.raw_format})
