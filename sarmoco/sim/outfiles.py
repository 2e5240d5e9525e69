"""``sarmoco sim --out DIR``: a run written as the files a flight would leave, plus the truth.

Files (each holds exactly the bytes the live link would carry):

============  ==================================================================
radar.vrt     VITA 49.2 packets back to back (:mod:`sarmoco.sim.emit_radar`)
nav.tlog      MAVLink 2 with 8-byte UNIX µs stamps; LOCAL_POSITION_NED and
              ATTITUDE_QUATERNION at the INS rate, SYSTEM_TIME at 5 Hz
ins.sbg       sbgECom binary as read from the serial port
ins.log       SBG CAN frames in candump format
truth.json    the run's truth (:meth:`SimRun.truth_dict`, each target's latitude and
              longitude added) and a ``wire`` section:
              what was written, the wire time base, the INS clock, the faults
              asked for and those injected per file
============  ==================================================================

The INS files are three recordings of the same INS (same samples, same clock).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.drivers.vita49 import PayloadFormat
from sarmoco.errors import DataFileError
from sarmoco.geodesy import ned_to_geodetic
from sarmoco.sim.emit_radar import RadarEmitter
from sarmoco.sim.emitter import Emitter, WireTime
from sarmoco.sim.faults import Faults
from sarmoco.sim.insemitters import INS_EMITTERS, InsEmitterOptions
from sarmoco.sim.insfeed import GEODETIC_ORIGIN, InsFeed
from sarmoco.sim.player import Pacing, play_emitters
from sarmoco.sim.run import SimRun
from sarmoco.sim.transports import FileLink

NAV_FILES = {name: kind.file for name, kind in INS_EMITTERS.items()}
"""File written for each INS protocol (:data:`~sarmoco.sim.insemitters.INS_EMITTERS`)."""
RADAR_FILE = "radar.vrt"
TRUTH_FILE = "truth.json"


def truth_record(
    run: SimRun,
    feed: InsFeed,
    faults: Faults,
    emitters: dict[str, Emitter],
    wire: WireTime,
) -> dict[str, Any]:
    """The run's truth plus what went on the wire (JSON-able).

    ``wire.shift_ns`` is added to every scenario GPS time on the wire (0 for files).
    Each target also gets ``lla`` (:func:`run_truth`): where a GIS should find it.
    """
    truth = run_truth(run)
    truth["wire"] = wire_record(feed, faults, emitters, wire)
    return truth


def run_truth(run: SimRun) -> dict[str, Any]:
    """The run's part of the truth record: :meth:`SimRun.truth_dict`, each target with its
    ``lla`` (latitude, longitude in deg, WGS-84 ellipsoid height in m) about
    :data:`~sarmoco.sim.insfeed.GEODETIC_ORIGIN`."""
    truth = run.truth_dict()
    for target in truth["targets"]:
        target["lla"] = ned_to_geodetic(np.asarray(target["pos_ned"]), GEODETIC_ORIGIN).tolist()
    return truth


def wire_record(
    feed: InsFeed, faults: Faults, emitters: dict[str, Emitter], wire: WireTime
) -> dict[str, Any]:
    """The ``wire`` section of the truth record: time base, INS clock, faults, links."""
    return {
        "shift_ns": wire.shift_ns,
        "leap_s": wire.leap_s,
        "ins_clock": feed.clock.to_dict(),
        "ins_latency_ns": feed.latency_ns,
        "ins_samples_sent": int(feed.t_ns.size),
        "faults": faults.to_dict(),
        "links": {name: {**e.describe(), "stats": e.stats()} for name, e in emitters.items()},
    }


class TruthWriter:
    """Writes one live run's truth record whenever asked, its run part serialized once.

    A 30-minute run's truth (every pulse's APC, every INS sample) is over 100 MB of JSON,
    tens of seconds to make: made before real-time playback, not between its start and
    its first event (which would then all be due at once). The file is what
    :func:`write_truth` writes of :func:`truth_record`.

    Parameters
    ----------
    path : Path
        The truth file.
    run : SimRun
    """

    def __init__(self, path: Path, run: SimRun) -> None:
        self.path = path
        self._run_json = json.dumps(run_truth(run))

    def write(
        self, feed: InsFeed, faults: Faults, emitters: dict[str, Emitter], wire: WireTime
    ) -> None:
        """Write the record with the ``wire`` section as it stands now."""
        wire_json = json.dumps(wire_record(feed, faults, emitters, wire))
        _write_atomic(self.path, f'{self._run_json[:-1]}, "wire": {wire_json}}}')


def write_truth(path: Path, truth: dict[str, Any]) -> None:
    """Write ``truth`` as JSON (atomically: a reader never sees half a file)."""
    _write_atomic(path, json.dumps(truth))


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_suffix(".json.tmp")
    try:
        tmp.write_text(text)
        tmp.replace(path)
    except OSError as exc:
        raise DataFileError(f"{path}: cannot write the truth record: {exc}") from exc


def write_run(
    run: SimRun,
    faults: Faults,
    out_dir: Path,
    *,
    nav: Sequence[str] = tuple(NAV_FILES),
    payload: PayloadFormat = "int16",
    stream_id: int = 0,
    seed: int = 0,
    pacing: Pacing | None = None,
) -> dict[str, Any]:
    """Write ``run`` into ``out_dir``; return the truth record (also in ``truth.json``).

    Parameters
    ----------
    run : SimRun
        The simulated run (its INS clock offset and drift must be ``faults``').
    faults : Faults
        Faults to inject (each file draws its own).
    out_dir : Path
        Directory, created if needed.
    nav : sequence of str
        INS recordings to write, by protocol name (keys of :data:`NAV_FILES`).
    payload : {"int16", "float32"}
        Radar I/Q format.
    stream_id : int
        VITA 49 stream ID.
    seed : int
        Seed of the fault draws.
    pacing : Pacing, optional
        Default: as fast as possible (the files do not depend on it).
    """
    unknown = set(nav) - set(NAV_FILES)
    if unknown:
        raise DataFileError(f"sim --out: unknown INS recording(s) {sorted(unknown)}")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataFileError(f"{out_dir}: cannot create: {exc}") from exc
    feed = InsFeed.from_run(run, faults)
    emitters: dict[str, Emitter] = {
        "radar": RadarEmitter(
            FileLink(out_dir / RADAR_FILE),
            run.scenario.radar,
            run.t_ns,
            run.echo,
            payload=payload,
            stream_id=stream_id,
            faults=faults.radar,
            seed=seed * 16,
            rank=0,
        ),
    }
    for k, proto in enumerate(nav, start=1):
        link = FileLink(out_dir / NAV_FILES[proto])
        options = InsEmitterOptions(faults.ins, seed * 16 + k, k)
        emitters[proto] = INS_EMITTERS[proto].to_file(link, feed, options)
    try:
        result = play_emitters(list(emitters.values()), pacing or Pacing(realtime=False))
    finally:
        for e in emitters.values():
            e.close()
    truth = truth_record(run, feed, faults, emitters, result.wire)
    write_truth(out_dir / TRUTH_FILE, truth)
    return truth
