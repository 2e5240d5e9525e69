"""``sarmoco run`` (the live daemon) and ``sarmoco replay`` (ground replay, virtual clock)."""

from __future__ import annotations

import datetime
import json
import logging
import math
import queue
import shutil
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from types import FrameType

from sarmoco.daemon.array_ingest import ArrayIngest
from sarmoco.daemon.array_pipeline import ArrayPipeline, ArraySummary
from sarmoco.daemon.camera import (
    SEVERITY_INFO,
    SEVERITY_WARNING,
    CameraComponent,
    Fault,
    ProductLog,
    operator_faults,
)
from sarmoco.daemon.config import Config, StatusConfig, live_imaging
from sarmoco.daemon.focuser import SinkFactory
from sarmoco.daemon.heap import HeapTrim
from sarmoco.daemon.ingest import RadarIngest
from sarmoco.daemon.links import open_ins, open_radar
from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.daemon.navbuffer import NavBuffer
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.sdnotify import Notifier
from sarmoco.daemon.status import Counters, Health, LiveView, StatusServer
from sarmoco.daemon.storeopen import open_recorder, record_ins_format
from sarmoco.daemon.tables import RunSummary
from sarmoco.daemon.threadcpu import stage_cpu_seconds
from sarmoco.daemon.warmup import warm_up_kernels
from sarmoco.drivers.radar import RadarFileSource, RadarSource, RadarTcpSource
from sarmoco.drivers.samples import Sample
from sarmoco.drivers.source import Source
from sarmoco.errors import ConfigError, DataFileError, RecorderError, SarmocoError
from sarmoco.store.reader import StoreNav, StorePulses, open_store
from sarmoco.store.recorder import Recorder

log = logging.getLogger(__name__)

_Link = RadarSource | Source
"""A radar or navigation link."""
_Pipe = Pipeline | ArrayPipeline
"""What records (and focuses or images) a live run's store: single-channel or array."""
_Ingest = RadarIngest | ArrayIngest
"""What reads the radar into a live run's echo ring."""

POLL_S = 0.05
"""Reader poll timeout and idle sleep of the focusing loop, s."""

RECORD_POLL_S = 0.01
"""Pause of the recording loop after each pass, s. A pass stores every pulse due, so the
next one finds what came meanwhile: about 200 pulses at 20 kHz, where passes back to back
would each store the few that came during the last one and pay a pass's fixed cost for
them."""

RECORDING_STALL_S = 0.5
"""WATCHDOG=1 waits while the recording thread has not ended a pass for this long, s."""

INS_ENDED_NOW_NS = 2**62
"""The aligner's "now" once an INS log file has ended, GPS ns (year 2116: after every pulse)."""

INS_STALE_S = 2.0
"""The INS counts as unhealthy when its newest sample is older than this (host clock), s."""

HEALTH_PERIOD_S = 0.1
"""Period of the links' and the INS's health checks (:meth:`_LiveRun._watch_links`), s."""

STRIP_NAV_LEAD_S = 2.0
"""A strip's store opens with the INS samples of this long before it (the first pulses'
navigation), s of INS time."""


def new_store_path(directory: str | Path, kind: str, item: int | None = None) -> Path:
    """A fresh store name ``<directory>/<kind>-<UTC time>.zarr`` (``...-item<item>.zarr``
    with a mission item)."""
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    suffix = "" if item is None else f"-item{item}"
    return Path(directory) / f"{kind}-{stamp}{suffix}.zarr"


REOPEN_S = 1.0
"""Pause between attempts to reopen a failed live link, s."""


FAILURE_LOCK = threading.Lock()
"""Held while a run checks a failure against the one it reported and records it (its
focusing loop and its recording thread both report)."""


@dataclass
class Capture:
    """One capture interval of a live run (the store's ``captures`` attribute).

    Attributes
    ----------
    start_utc : str
        When the capture started, UTC, ISO 8601.
    stop_utc : str or None
        When it stopped, UTC, ISO 8601 (None while capturing, or when the run ended in it).
    """

    start_utc: str
    stop_utc: str | None = None


@dataclass
class _Strip:
    """The store of one capture (``camera.store_per_capture``), while it is open."""

    number: int
    """1 for the daemon's first strip, and so on."""
    path: Path
    capture: Capture
    mission_item: int | None
    """The mission item current when the capture started (None: none reported)."""


@dataclass
class _LiveState:
    stop: threading.Event
    last_nav_mono: float = 0.0
    last_pulse_mono: float = 0.0
    recorded_mono: float = 0.0
    """When the recording thread last ended a pass (host monotonic clock), s."""
    first_pulse_mono: float = 0.0
    link_down: str = ""
    ins_bus_fault: str = ""
    """What the INS link's adapter reports wrong with its bus (CAN bus-off), if anything."""
    finished: set[str] = field(default_factory=set)
    """Links that were files and reached their end (not a failure)."""
    heap: HeapTrim = field(default_factory=HeapTrim)
    """Hands the pages focusing freed back to the system after its passes."""


def _keep_reading(
    name: str,
    opener: Callable[[], _Link],
    first: _Link,
    read: Callable[[_Link], int],
    st: _LiveState,
) -> None:
    """Read a link until stop; reopen it when it fails or its peer goes away.

    File links (a log given to ``run``) end at their end of file instead: the link
    is then *finished* (``st.finished``), which is not a failure.
    """
    link: _Link | None = first
    while not st.stop.is_set():
        try:
            if link is None:
                link = opener()
                log.info("link reopened", extra={"link": name})
                st.link_down = ""
            if read(link) or not link.eof:
                continue  # at end of stream, read until what was buffered is out
            if not isinstance(link, RadarTcpSource):  # only files end; a TCP peer may return
                st.finished.add(name)
                log.info("link finished: end of file", extra={"link": name})
                break
            reason = "peer closed the link"
        except SarmocoError as exc:  # the link itself failed: port gone, socket refused
            reason = str(exc)
        st.link_down = f"{name}: {reason}"
        log.error("link down, reopening", extra={"link": name, "error": reason})
        if link is not None:
            link.close()
            link = None
        st.stop.wait(REOPEN_S)
    if link is not None:
        link.close()


def _finished_text(names: list[str]) -> str:
    """How status and health name file links that reached their end."""
    return "; ".join(f"{name}: finished (end of file)" for name in names)


def _start_status(
    counters: Counters, health: Health, cfg: StatusConfig, store: Path, live: LiveFeed
) -> StatusServer | None:
    """The status endpoint on 127.0.0.1:``cfg.http_port`` with the live page of ``live``,
    the feed of the recorder of ``store`` (None: port 0).

    Raises
    ------
    ConfigError
        If the port cannot be bound (in use, or privileged).
    """
    port = cfg.http_port
    if not port:
        return None
    view = LiveView(store, live, cfg.live_render_interval_s)
    try:
        return StatusServer(counters, health, port=port, live=view).start()
    except OSError as exc:
        raise ConfigError(f"status.http_port: {port} cannot be bound: {exc.strerror}") from exc


def run_live(cfg: Config, store: Path | None = None, idle_exit_s: float | None = None) -> int:
    """Run the daemon until SIGTERM/SIGINT (or ``idle_exit_s`` without pulses after the first).

    Parameters
    ----------
    cfg : Config
        The configuration.
    store : Path, optional
        Store to create (default: a new name in ``recorder.directory``).
    idle_exit_s : float, optional
        Stop cleanly once no radar pulse has arrived for this long (simulation, tests).

    Returns
    -------
    int
        Exit status 0 (a clean stop). A link that fails is reopened every second
        meanwhile; while it is down the daemon reports itself unhealthy and stops
        sending WATCHDOG=1, so systemd restarts it if the outage lasts. A file link
        that reaches its end is finished, not failed: health and ``STATUS=`` say so
        and the keep-alive goes on.
    """
    stop = threading.Event()
    _stop_on_signals(stop)
    if store is None and _per_capture(cfg):
        store = Path(cfg.recorder.directory) / "strip.zarr"  # strips strip-<UTC time>.zarr
    run = _LiveRun(cfg, store or new_store_path(cfg.recorder.directory, "run"), stop)
    try:
        run.supervise(idle_exit_s)
    except Exception:  # logged here: an error while shutting down would hide it
        log.exception("sarmoco stopping on an unexpected error")
        raise
    finally:
        run.shut_down()
    return 0


def _per_capture(cfg: Config) -> bool:
    """Whether the run opens a store per capture (``camera.store_per_capture``)."""
    return cfg.camera.enabled and cfg.camera.store_per_capture


def _stop_on_signals(stop: threading.Event) -> None:
    """Set ``stop`` on SIGTERM (systemd) and SIGINT (Ctrl-C)."""

    def on_term(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)


class _LiveRun:
    """A live run: status endpoint, store, links, reader threads, the recording thread,
    and the focusing loop (see :mod:`sarmoco.daemon.pipeline`).

    The recording thread stores every pulse and the INS log as they come, whatever
    focusing does; the focusing loop (the calling thread) may lag, and skips ahead when
    it falls behind (not with a radar file link: a file waits for focusing).

    The processing's numba kernels are compiled (or loaded from numba's cache) first,
    before the links open and READY=1 (:func:`~sarmoco.daemon.warmup.warm_up_kernels`).

    In array mode (``radar.mode = "array"``) the pipeline is an
    :class:`~sarmoco.daemon.array_pipeline.ArrayPipeline`: the reader groups every Tx/Rx
    pair's packets into whole pulses, the recording thread stores them per channel as they
    come, the focusing loop aligns them with the INS, and closing the store (the daemon's
    stop, or a strip's) forms its DEMs, announced by the camera component.

    With ``camera.enabled`` the MAVLink camera component (:mod:`sarmoco.daemon.camera`)
    runs beside, and the ground station starts and stops the capture: outside a capture
    the radar's pulses are read and let go (``pulses_not_captured``). The capture
    intervals go to the store's ``captures`` attribute at the end of the run.

    With ``camera.store_per_capture`` each capture has a store of its own (a strip): a
    start capture opens ``<path's folder>/<path's stem>-<UTC time>[-item<N>].zarr`` (N the
    mission item the autopilot reported current), a stop closes it complete (every pulse
    recorded and focused, the run's metrics, its ``captures`` and ``strip`` attributes),
    and the camera component announces it (CAMERA_IMAGE_CAPTURED at the strip's middle,
    and a STATUSTEXT). The focusing loop's thread opens and closes the stores, between
    passes; the recording thread lets go of a store under :attr:`_record_lock`, the INS
    reader under :attr:`_nav_lock`. Between strips no pipeline runs (:attr:`pipe` is
    None): pulses are read and let go, INS samples only kept for the next strip's start
    (:data:`STRIP_NAV_LEAD_S`).

    Parameters
    ----------
    cfg : Config
        The configuration.
    path : Path
        Store to create (with ``camera.store_per_capture``: what the strips are named by).
    stop : threading.Event
        Set to end the run (by a signal).
    """

    def __init__(self, cfg: Config, path: Path, stop: threading.Event) -> None:
        self.cfg = cfg
        self.path = path
        self.notifier = Notifier()
        # before the links: nothing waits for a compile
        warm_up_kernels(live_imaging(cfg), self.notifier)
        self.counters, self.health = Counters(), Health()
        self.st = _LiveState(stop)
        self.per_capture = _per_capture(cfg)
        """A store per capture (``camera.store_per_capture``), not one for the run."""
        self.live = LiveFeed()
        store_dir = path.parent if self.per_capture else path
        self.status = _start_status(self.counters, self.health, cfg.status, store_dir, self.live)
        self.products = ProductLog(self.live, path, cfg.geometry.height_m,
                                   cfg.ins.gps_minus_utc_s)  # fmt: skip
        """The tiles stored and where the antenna was (the camera component announces them)."""
        radar = open_radar(cfg)
        self.ins = open_ins(cfg, keep_raw=cfg.recorder.raw_ins)
        """The INS link as first opened (its raw format names the stores' raw bytes)."""
        self._network = not isinstance(radar, RadarFileSource)
        """The radar link is a network link (not a file)."""
        self._write_failure_reported = False
        """The recorder's writer thread failed and that was counted and logged."""
        self._record_lock = threading.Lock()
        """Held by the recording thread through a pass, and to change :attr:`pipe`."""
        self._nav_lock = threading.Lock()
        """Held by the INS reader while it offers samples, and to change :attr:`pipe`."""
        self._ingest = self._new_ingest()
        """What reads the radar: the open strip's pipeline's, else one that lets the pulses
        go (or, while a strip opens, keeps them for its pipeline to take over)."""
        self.pipe: _Pipe | None = None if self.per_capture else self._new_pipeline(path)
        """The pipeline of the open store (None between strips)."""
        self.strip: _Strip | None = None
        """The open strip (``camera.store_per_capture``; None: none open)."""
        self._strips = 0
        """Strips opened so far."""
        self._strip_requests: queue.SimpleQueue[tuple[bool, int | None]] = queue.SimpleQueue()
        """Start (True) and stop capture requests with their mission item, oldest first."""
        self._taking = False
        """The open strip takes pulses (False from a stop capture until the strip closes)."""
        self._opening = False
        """A start capture asks for a strip not open yet: the pulses read meanwhile are kept
        for it (not let go)."""
        self._recent_nav: deque[Sample] = deque()
        """INS samples of the last :data:`STRIP_NAV_LEAD_S` (a new strip starts with them)."""
        self.last_summary: RunSummary | ArraySummary = RunSummary()
        """The totals of the last store closed (or of the run's one store at its end)."""
        self._pulses_closed = 0
        """Pulses received by the strips closed so far."""
        self._ins_file = Path(cfg.ins.link).is_file()
        """The INS link is a log file, read at its own pace (see :meth:`_now_ns`)."""
        self._ins_backlog: deque[Sample] = deque()
        """Samples read from an INS log and not yet offered (:meth:`_read_ins_file`)."""
        self._recording_failure: SarmocoError | None = None
        """The last pass of the recording thread failed (None: it succeeded)."""
        self.counters.add_source("radar", radar.decoder.counters.snapshot)
        self.decoder = radar.decoder
        """The radar's decoder (the same across reconnections): the streams it skipped."""
        self.counters.add_source("ins", self.ins.counters.snapshot)
        self.counters.add_source("cpu_seconds", stage_cpu_seconds)
        self.counters.inc("processing_busy_seconds", 0.0)
        self.captures: list[Capture] = []
        """Capture intervals, oldest first."""
        self.camera = self._start_camera() if cfg.camera.enabled else None
        """The MAVLink camera component (None: ``camera.enabled`` off)."""
        if self.camera is None or self.camera.capturing:
            self._capture(True, None)
        self._change_strips()  # the first strip, capturing from the start
        ins = self.ins
        self.threads = [
            self._reader(
                "radar", lambda: open_radar(cfg, decoder=radar.decoder), radar, self._read_radar
            ),
            self._reader(
                "ins", lambda: open_ins(cfg, keep_raw=cfg.recorder.raw_ins), ins, self._read_ins
            ),
        ]
        self.recording = threading.Thread(target=self._keep_recording, name="recording",
                                          daemon=True)  # fmt: skip
        self.recording.start()
        self._links_ok = False
        """Every link up at the last look of :meth:`_watch_links` (WATCHDOG=1 needs it)."""
        self.monitor = threading.Thread(target=self._watch_links, name="health", daemon=True)
        self.monitor.start()
        named = f"{path.parent / path.stem}-*.zarr" if self.per_capture else str(path)
        log.info("sarmoco running", extra={"store": named, "radar": cfg.radar.link,
                                            "ins": cfg.ins.link})  # fmt: skip
        port = self.status.port if self.status else 0
        print(json.dumps({"store": named, "status_port": port}), flush=True)
        self.notifier.ready(f"recording to {named}")

    @property
    def recorder(self) -> Recorder:
        """The recorder of the open store.

        Raises
        ------
        RecorderError
            Between strips (``camera.store_per_capture``): no store is open.
        """
        if self.pipe is None:
            raise RecorderError("recorder: no store is open between strips")
        return self.pipe.recorder

    def _new_ingest(self) -> _Ingest:
        """A radar ingest of its own (an echo ring, the reads that fill it): whole pulses of
        every Tx/Rx pair in array mode."""
        if self.cfg.radar.mode == "array":
            return ArrayIngest(self.cfg, self.counters)
        return RadarIngest(self.cfg, NavBuffer(), self.counters, refuse_jumps=self._network)

    def _new_pipeline(self, path: Path) -> _Pipe:
        """A new store at ``path`` and the pipeline that records and focuses (array mode:
        images at its end) into it, taking over :attr:`_ingest` (and the pulses in its
        ring)."""
        recorder = open_recorder(self.cfg, path, self.live)
        record_ins_format(recorder, self.ins)
        self._write_failure_reported = False
        ingest = self._ingest
        if isinstance(ingest, ArrayIngest):
            return ArrayPipeline(self.cfg, recorder, self.counters, ingest, self._network)
        return Pipeline(
            live_imaging(self.cfg), recorder, self.counters, refuse_jumps=self._network,
            focus_skips=self._network, radar=ingest,
        )  # fmt: skip

    # -- the camera component ---------------------------------------------------------------

    def _start_camera(self) -> CameraComponent:
        """The MAVLink camera component on ``camera.link``, started."""
        cam = self.cfg.camera
        carrier_ghz = self.cfg.radar.carrier_hz / 1e9
        return CameraComponent(
            cam, cam.model or f"SAR {carrier_ghz:g} GHz", self._operator_faults,
            self._free_bytes, self._capture, self.counters, self.products.products,
        ).start()  # fmt: skip

    def _disk_usage(self) -> tuple[int, int] | None:
        """Free and total bytes of the store's file system (None: unknown)."""
        try:
            usage = shutil.disk_usage(self.path.parent)
        except OSError:
            return None
        return usage.free, usage.total

    def _free_bytes(self) -> int | None:
        usage = self._disk_usage()
        return None if usage is None else usage[0]

    def _operator_faults(self) -> dict[str, Fault]:
        """The faults the camera component announces (:func:`operator_faults`)."""
        usage = self._disk_usage()
        free = None if usage is None or not usage[1] else usage[0] / usage[1]
        gauges = self.counters.snapshot()["gauges"]
        low = self.cfg.camera.disk_low_fraction
        return operator_faults(self.health.components(), gauges, free, low)

    def _capture(self, on: bool, mission_item: int | None) -> None:
        """Open (``on``) or close a capture interval: pulses are recorded only within one.

        With a store per capture, ask the focusing loop to open or close a strip
        (:meth:`_change_strips`; pulses are let go from a stop on); ``mission_item`` names
        the strip's store (None: no mission item).
        """
        if self.per_capture:
            if on:
                self._opening = True
            else:
                self._taking = False
            self._strip_requests.put((on, mission_item))
            return
        now = datetime.datetime.now(datetime.UTC).isoformat()
        if on:
            self.captures.append(Capture(now))
        elif self.captures and self.captures[-1].stop_utc is None:
            self.captures[-1].stop_utc = now
        log.info("capture started" if on else "capture stopped", extra={"store": str(self.path)})

    def _capturing(self, ingest: _Ingest) -> bool:
        """Whether pulses read into ``ingest`` are kept now (always without the camera
        component). With a store per capture: while it is the current ingest, and a strip
        is open and taking pulses, or none is open and one is opening."""
        if self.per_capture:
            taking = self._taking if self.strip is not None else self._opening
            return taking and ingest is self._ingest
        return self.camera is None or self.camera.capturing

    # -- strips (a store per capture) -------------------------------------------------------

    def _change_strips(self) -> None:
        """Open and close strips as the start and stop capture requests ask (the focusing
        loop's thread, between passes). A start that came while the last strip was closing
        keeps its pulses until its strip is open: only the start's own request ends
        :attr:`_opening`."""
        while True:
            try:
                on, item = self._strip_requests.get_nowait()
            except queue.Empty:
                return
            if on and self.strip is None:
                self._open_strip(item)
            elif not on and self.strip is not None:
                self._close_strip()
            if on:
                self._opening = False

    def _open_strip(self, mission_item: int | None) -> None:
        """Open the next strip's store and let it take pulses, with the INS samples of the
        last :data:`STRIP_NAV_LEAD_S`. A store that cannot be created is a processing
        error (counted, logged, announced): no strip opens, the daemon runs on."""
        path = new_store_path(self.path.parent, self.path.stem, mission_item)
        try:
            pipe = self._new_pipeline(path)
        except SarmocoError as exc:
            self._processing_failed(exc)
            return
        self._strips += 1
        self.products.open_store(path)
        now = datetime.datetime.now(datetime.UTC).isoformat()
        # taking before the strip is seen: the reader asks _taking once a strip is open
        self._taking = True
        with self._nav_lock, self._record_lock:
            pipe.add_nav(list(self._recent_nav), None)
            self.pipe = pipe
            self.strip = _Strip(self._strips, path, Capture(now), mission_item)
        log.info("strip opened", extra={"store": str(path), "strip": self._strips,
                                         "mission_item": mission_item})  # fmt: skip

    def _close_strip(self) -> None:
        """Close the open strip's store complete (every pulse recorded and focused, its
        metrics and attributes) and announce it. A failure to focus or write its last
        part is a processing error (counted, logged, announced); the store is closed with
        what it holds."""
        strip, pipe = self.strip, self.pipe
        assert strip is not None and pipe is not None
        self._taking = False
        with self._nav_lock, self._record_lock:
            self.pipe, self.strip = None, None
            self._ingest = self._new_ingest()
        strip.capture.stop_utc = datetime.datetime.now(datetime.UTC).isoformat()
        summary = pipe.current()
        try:
            summary = pipe.finish()
            pipe.recorder.set_attribute("captures", {"intervals": [asdict(strip.capture)]})
            pipe.recorder.set_attribute(
                "strip", {"number": strip.number, "mission_item": strip.mission_item}
            )
        except SarmocoError as exc:  # the store keeps what was committed; the daemon runs on
            self._processing_failed(exc)
        finally:  # a processing error in the last blocks must not leave the store open
            try:
                pipe.recorder.close()
            except SarmocoError as exc:
                self._processing_failed(exc)
        self.last_summary = summary
        self._pulses_closed += summary.pulses_received
        log.info("strip closed", extra=summary.as_dict() | {"store": str(strip.path)})
        self._announce_strip(strip, pipe, summary.pulses_received)
        self._announce_dem(summary)

    def _announce_strip(self, strip: _Strip, pipe: _Pipe, pulses: int) -> None:
        """CAMERA_IMAGE_CAPTURED (placed at the middle of its pulses) and a STATUSTEXT for a
        closed strip; a strip without pulses only the STATUSTEXT, at warning."""
        camera = self.camera
        item = "" if strip.mission_item is None else f" item {strip.mission_item}"
        first, last = pipe.radar.first_and_latest_ns()
        if first is None or last is None:
            if camera is not None:
                camera.notify(SEVERITY_WARNING, f"SAR: strip {strip.number}{item} empty")
            return
        self.products.add_strip(strip.path, first, last)
        if camera is not None:
            text = f"SAR: strip {strip.number}{item} stored, {pulses} pulses"
            camera.notify(SEVERITY_INFO, text)

    def _announce_dem(self, summary: RunSummary | ArraySummary) -> None:
        """A STATUSTEXT for the DEM an array store's end formed (``SAR: DEM 17272 cells of
        61 pulses``: the valid cells of the first product), at warning when none was;
        nothing for a single-channel store, or without the camera component."""
        if self.camera is None or not isinstance(summary, ArraySummary):
            return
        dem = next(iter(summary.dem.values()), None)
        if dem is None:
            self.camera.notify(SEVERITY_WARNING, "SAR: no DEM formed")
            return
        text = f"SAR: DEM {int(dem['valid_cells'])} cells of {summary.pulses_imaged} pulses"
        self.camera.notify(SEVERITY_INFO, text)

    # -- reader threads ---------------------------------------------------------------------

    def _reader(
        self,
        name: str,
        opener: Callable[[], _Link],
        first: _Link,
        read: Callable[[_Link], int],
    ) -> threading.Thread:
        """Start the thread that keeps reading one link (:func:`_keep_reading`)."""
        thread = threading.Thread(
            target=_keep_reading, args=(name, opener, first, read, self.st), name=name, daemon=True
        )
        thread.start()
        return thread

    def _read_radar(self, link: _Link) -> int:
        """Read pulses into the ring (a file waits for room instead of dropping); with a
        store per capture, into the open strip's, let go between strips, and kept for the
        strip while it opens)."""
        assert isinstance(link, RadarSource)
        ingest = self._ingest
        limit = self.cfg.imaging.block_pulses
        if isinstance(link, RadarFileSource):
            limit = min(limit, ingest.ring.free)
            if not limit:
                self.st.stop.wait(POLL_S)
                return 0
        n = ingest.read(link, POLL_S, limit, capturing=lambda: self._capturing(ingest))
        if n:
            self.st.last_pulse_mono = time.monotonic()
            self.st.first_pulse_mono = self.st.first_pulse_mono or self.st.last_pulse_mono
        return n

    def _read_ins(self, link: _Link) -> int:
        """Offer INS samples and the bytes they came in to the pipeline."""
        assert isinstance(link, Source)
        if self._ins_file:
            return self._read_ins_file(link)
        samples = link.poll(POLL_S)
        rx_ns = time.monotonic_ns()
        self.st.ins_bus_fault = link.bus_fault
        raw = link.take_raw()
        with self._nav_lock:
            if self.pipe is not None:
                self.pipe.add_ins_raw(raw, rx_ns)
            if samples:
                self._offer_nav(samples, rx_ns)
        return len(samples)

    def _offer_nav(self, samples: list[Sample], rx_ns: int | None) -> None:
        """Offer INS samples to the open store's pipeline and keep their fixes and (with a
        store per capture) the last :data:`STRIP_NAV_LEAD_S` of them; :attr:`_nav_lock` held."""
        self.st.last_nav_mono = time.monotonic()
        self.products.add_fixes(samples)
        if self.per_capture:
            recent = self._recent_nav
            recent.extend(samples)
            while recent[-1].t_gps_ns - recent[0].t_gps_ns > STRIP_NAV_LEAD_S * 1e9:
                recent.popleft()
        if self.pipe is not None:
            self.pipe.add_nav(samples, rx_ns)

    def _read_ins_file(self, link: Source) -> int:
        """Offer an INS log's samples no further ahead of the radar than the nav history.

        A file is read as fast as the disk allows, many seconds of samples in one poll.
        Offered at once, they would push the samples the waiting pulses need out of the
        nav buffer's history, so they wait here until the radar comes within half the
        history (:meth:`_ins_horizon_ns`). The read time of a file says nothing of when
        the INS sent a sample: no receive time goes with them (no latency check); the
        bytes are recorded with the time they were read.

        Returns
        -------
        int
            Samples offered plus samples still waiting (non-zero while any wait, so the
            link is not finished before they are offered).
        """
        backlog = self._ins_backlog
        if not backlog:
            backlog.extend(link.poll(POLL_S))
            raw = link.take_raw()
            with self._nav_lock:
                if self.pipe is not None:
                    self.pipe.add_ins_raw(raw, time.monotonic_ns())  # when it was read
        horizon = self._ins_horizon_ns()
        offer = []
        while backlog and (horizon is None or backlog[0].t_gps_ns <= horizon):
            offer.append(backlog.popleft())
        if offer:
            with self._nav_lock:
                self._offer_nav(offer, None)
        elif backlog:
            self.st.stop.wait(POLL_S)
        return len(offer) + len(backlog)

    def _ins_horizon_ns(self) -> int | None:
        """Newest INS time an INS log may be offered up to, GPS ns (None: no limit).

        Half the nav buffer's history past the oldest pulse still waiting for its
        navigation, wherever it waits (echo ring or focus backlog: the samples it needs
        then stay within the history however far the file is read ahead), else (before
        the first pulse) past the oldest sample held or waiting. No limit once the radar
        link has finished and every pulse has been taken by the aligner, nor while no
        store is open.
        """
        pipe = self.pipe
        if pipe is None:
            return None
        oldest, all_aligned = pipe.oldest_unaligned_ns()
        if all_aligned and "radar" in self.st.finished:
            return None
        if oldest is not None:
            reference = oldest
        elif (span := pipe.nav.span_ns()) is not None:
            reference = span[0]
        elif self._ins_backlog:
            reference = self._ins_backlog[0].t_gps_ns
        else:
            return None
        return reference + pipe.nav.kinematics.history_ns // 2

    # -- recording thread ---------------------------------------------------------------------

    def _keep_recording(self) -> None:
        """Store the pulses and INS samples as they come, until stop (the pulses still in
        the ring then are stored by :meth:`Pipeline.finish`).

        A failed pass (a store write refused) is counted, logged and reported unhealthy
        (``processing``) until a pass succeeds; the pulses of the refused write are not
        stored (nor focused), those after it wait in the ring for the next pass.
        """
        while not self.st.stop.is_set():
            try:
                with self._record_lock:
                    pipe = self.pipe
                    if pipe is not None:
                        pipe.record(pipe.now_ns(live=True))
                        pipe.recorder.flush_due()
            except SarmocoError as exc:
                self._recording_failure = exc
                self._processing_failed(exc)
                self.st.stop.wait(POLL_S)
                continue
            self._recording_failure = None
            self.st.recorded_mono = time.monotonic()
            self.st.stop.wait(RECORD_POLL_S)

    # -- focusing loop ------------------------------------------------------------------------

    def _now_ns(self) -> int | None:
        """The aligner's "now": the radar clock, held back to the INS log's progress.

        :meth:`Pipeline.now_ns` (the newest pulse plus the host time since it came) is
        "now" for links that deliver data as it happens. An INS log file is read at its
        own pace: until it ends, a pulse beyond what it has delivered is waiting for the
        read, not for an INS that is late, so "now" goes no further than the newest
        sample both INS streams hold (None: wait for the first). Once the log has ended no
        pulse can gain navigation by waiting: "now" is then :data:`INS_ENDED_NOW_NS` (a pulse
        time-stamped an hour ahead by a hostile sender would otherwise wait for ever).
        """
        assert self.pipe is not None
        now = self.pipe.now_ns(live=True)
        if now is None or not self._ins_file:
            return now
        if "ins" in self.st.finished:
            return INS_ENDED_NOW_NS  # no sample will come: every waiting pulse is decided now
        span = self.pipe.nav.span_ns()
        return None if span is None else min(now, span[1])

    def supervise(self, idle_exit_s: float | None) -> None:
        """Focus, report health and status, until stopped (or idle for ``idle_exit_s``).

        The wall time spent in focusing passes that released pulses is counted
        (``processing_busy_seconds``): data seconds focused over it is how many times
        faster than real time focusing could run (``sarmoco bench``'s ``realtime_ratio``).
        """
        while not self.st.stop.is_set():
            self._change_strips()
            start = time.monotonic()
            released = self._process()
            now = time.monotonic()
            if released:
                self.counters.inc("processing_busy_seconds", now - start)
            self._keepalive()
            if self._idle(now, idle_exit_s):
                break
            if released == 0:
                time.sleep(POLL_S)

    def _process(self) -> int:
        """One focusing pass of the pipeline; returns the pulses released.

        A processing error loses only this block's focus (its pulses are recorded): it
        is counted and reported unhealthy until a pass succeeds (and the recording
        thread's last pass did); a store write failure until a write succeeds
        (:attr:`Recorder.write_failure`; a pass with nothing to write does not clear
        it). A write that failed on the recorder's writer thread
        (``recorder.writer_queue``) is raised by the next call to the recorder; if no
        call was made after it, it is counted and reported here, once, and processing
        stays unhealthy (the thread writes nothing after it). Nothing while no store is
        open. After a pass that focused, the heap's free pages go back to the system
        (:class:`~sarmoco.daemon.heap.HeapTrim`), so the resident memory follows what
        focusing holds rather than the most it ever held.
        """
        if self.pipe is None:
            return 0
        try:
            released = self.pipe.focus(self._now_ns(), on_block=self._block_done)
        except SarmocoError as exc:
            self._processing_failed(exc)
            return 0
        if released:
            self.st.heap.maybe_trim()
        failure = self.pipe.recorder.write_failure
        if failure is None:
            if self._recording_failure is None:
                self.health.set("processing", True)
        elif not self._write_failure_reported:
            self._processing_failed(failure)
        return released

    def _processing_failed(self, exc: SarmocoError) -> None:
        """Count, log and report unhealthy a failed pass (or writer thread).

        With ``recorder.writer_queue``, the writer thread's failure stands: every later
        call to the recorder raises it again, from the focusing loop and from the
        recording thread. Once reported, it is not counted or logged again.
        """
        self.health.set("processing", False, str(exc))
        pipe = self.pipe
        standing = None if pipe is None else pipe.recorder.write_failure
        queued = self.cfg.recorder.writer_queue > 0
        with FAILURE_LOCK:
            if queued and self._write_failure_reported and str(exc) == str(standing):
                return
            self._write_failure_reported = standing is not None
        self.counters.inc("processing_errors")
        log.error("processing error, block skipped", extra={"error": str(exc)})

    def _block_done(self) -> None:
        """A block was focused within a pass: :meth:`_keepalive`. A pass through a backlog
        under load can take longer than ``WatchdogSec``; a stalled one makes no block and
        sends nothing."""
        self._keepalive()

    def _keepalive(self) -> None:
        """WATCHDOG=1 (at most every half period) if the links were up at the last check
        and the recording thread ended a pass within :data:`RECORDING_STALL_S`: a store
        that does not answer stalls recording, and systemd is to hear it."""
        recorded = self.st.recorded_mono
        if self._links_ok and time.monotonic() - recorded < RECORDING_STALL_S:
            self.notifier.keepalive()

    def _watch_links(self) -> None:
        """Keep the links' and the INS's health current every ``HEALTH_PERIOD_S``, and the
        age gauges and ``STATUS=`` every second, on their own thread: a processing pass
        through a backlog can take seconds, and /status must show a link or INS fault
        while it lasts (set between passes, a 0.4 s CAN bus fault showed in no read)."""
        last_status = -math.inf
        while not self.st.stop.wait(HEALTH_PERIOD_S):
            now = time.monotonic()
            self._links_ok = self._update_health(now)
            if now - last_status >= 1.0:
                last_status = now
                self._publish_status(now)

    def _nav_age(self, now: float) -> float:
        """Age of the newest INS sample (host clock), s; infinite before the first."""
        return now - self.st.last_nav_mono if self.st.last_nav_mono else float("inf")

    def _update_health(self, now: float) -> bool:
        """Set the ``links`` and ``ins`` health checks and the INS and radar age gauges;
        returns whether every link is up.

        A reader that stopped because its file ended is not down; an INS log read to its
        end is healthy however old its last sample. The INS is unhealthy while its link's
        adapter reports a bus fault (CAN error passive or bus-off; the link stays up).
        ``radar_age_seconds``: host time since the radar link last gave a pulse (infinite
        before the first): a stalled peer shows here while the link stays up.
        """
        st, ended = self.st, sorted(self.st.finished)
        ok = all(t.is_alive() or t.name in ended for t in self.threads) and not st.link_down
        self.health.set("links", ok, st.link_down or _finished_text(ended))
        nav_age = self._nav_age(now)
        self.counters.set("ins_age_seconds", nav_age)
        last_pulse = st.last_pulse_mono
        self.counters.set("radar_age_seconds", now - last_pulse if last_pulse else math.inf)
        ins_detail = f"newest sample {nav_age:.2f} s old"
        if "ins" in ended:  # a log read to its end: no newer sample will come
            ins_detail = f"{_finished_text(['ins'])}, {ins_detail}"
        if st.ins_bus_fault:
            ins_detail = f"{st.ins_bus_fault}, {ins_detail}"
        fresh = nav_age < INS_STALE_S or "ins" in ended
        self.health.set("ins", fresh and not st.ins_bus_fault, ins_detail)
        self._radar_streams()
        return ok

    def _radar_streams(self) -> None:
        """Set the ``radar`` health check once signal packets of other VITA streams than the
        decoded one arrived: unhealthy while none of the decoded stream came (the detail
        names the streams that arrived and ``radar.stream_id``), healthy after."""
        skipped = sorted(self.decoder.skipped_streams)  # one C call: no lock needed
        if not skipped:
            return
        sid = self.decoder.stream_id
        arrived = ", ".join(f"{s} (0x{s:08x})" for s in skipped)
        if self._pulses_received() == 0:
            self.health.set(
                "radar",
                False,
                f"no signal packet of VITA stream {sid} (radar.stream_id); signal packets of "
                f"streams {arrived} arrived and are skipped: set radar.stream_id to one of them",
            )
        else:
            self.health.set(
                "radar", True, f"decoding VITA stream {sid} (radar.stream_id); skipping {arrived}"
            )

    def _pulses_received(self) -> int:
        """Pulses received into the run's stores so far."""
        pipe = self.pipe
        return self._pulses_closed + (0 if pipe is None else pipe.summary.pulses_received)

    def _publish_status(self, now: float) -> None:
        """The systemd ``STATUS=`` line."""
        nav_age = self._nav_age(now)
        ended = sorted(self.st.finished)
        pipe = self.pipe
        backlog = f"backlog {len(pipe.ring)}" if pipe is not None else "no capture"
        self.notifier.status(
            f"{self._pulses_received()} pulses, INS age {nav_age:.2f} s, "
            f"{backlog}{'; ' if ended else ''}{_finished_text(ended)}"
        )

    def _idle(self, now: float, idle_exit_s: float | None) -> bool:
        """Whether no pulse came for ``idle_exit_s`` since pulses began (None: never) and,
        with an INS log, every pulse has been aligned (its samples are offered only as
        the pulses need them)."""
        st, pipe = self.st, self.pipe
        return (
            idle_exit_s is not None
            and bool(st.first_pulse_mono)
            and (now - st.last_pulse_mono > idle_exit_s)
            and (not self._ins_file or pipe is None or pipe.oldest_unaligned_ns()[1])
        )

    def shut_down(self) -> None:
        """Stop the readers, record and focus what is left, close the store and endpoints."""
        self.notifier.stopping()
        self.st.stop.set()
        for t in [*self.threads, self.recording, self.monitor]:
            t.join(timeout=5.0)
        pipe = self.pipe
        try:
            if self.strip is not None:
                self._close_strip()
            elif pipe is not None:  # the run's one store
                self.last_summary = pipe.finish()
                intervals = [asdict(c) for c in self.captures]
                pipe.recorder.set_attribute("captures", {"intervals": intervals})
                first, last = pipe.radar.first_and_latest_ns()
                if isinstance(pipe, ArrayPipeline) and first is not None and last is not None:
                    self.products.add_strip(self.path, first, last)  # the DEM's store
                self._announce_dem(self.last_summary)
        finally:  # a processing error in the last blocks must not leave the store open
            if self.camera is not None:  # after the last tiles: it announces them
                self.camera.stop()
            if pipe is not None and not self.per_capture:
                pipe.recorder.close()
            if self.status is not None:
                self.status.stop()
            self.notifier.close()
        log.info("sarmoco stopped", extra=self.last_summary.as_dict() | {"store": str(self.path)})


def replay_files(
    cfg: Config,
    radar_file: Path,
    nav_file: Path,
    out: Path,
    progress: bool = True,
    sink: SinkFactory | None = None,
) -> RunSummary:
    """Replay a ``.vrt`` radar file and an INS log through the pipeline on a virtual clock
    (see :func:`_replay`; ``sink``: imaging deferred, see :class:`Pipeline`)."""
    total = max(radar_file.stat().st_size, 1)
    with (
        open_radar(cfg, str(radar_file)) as radar,
        open_ins(cfg, str(nav_file), keep_raw=cfg.recorder.raw_ins) as ins,
    ):
        done = (lambda: radar.decoder.counters.bytes / total) if progress else None
        return _replay(cfg, radar, ins, out, done, sink)


def replay_store(
    cfg: Config,
    recording: Path,
    out: Path,
    progress: bool = True,
    sink: SinkFactory | None = None,
) -> RunSummary:
    """Replay a recorded store (raw echoes and INS samples as received) through the pipeline.

    The pulses are read into the pipeline as a radar file is, and the INS samples the
    live run accepted are offered again in time order (:class:`StorePulses`,
    :class:`StoreNav`), both through :func:`_replay`. The recording's raw INS bytes are
    carried over (unless ``recorder.raw_ins`` is off). ``sink``: imaging deferred (see
    :class:`Pipeline`).
    """
    src = open_store(recording, skip_damaged=True)
    with StorePulses(src) as radar, StoreNav(src) as ins:
        if cfg.recorder.raw_ins:
            ins.keep_raw()
        summary = _replay(
            cfg, radar, ins, out, (lambda: radar.fraction) if progress else None, sink
        )
    if src.skipped:
        log.warning("%s", src.damage_text())
    return summary


def _replay(
    cfg: Config,
    radar: RadarSource | StorePulses,
    ins: Source,
    out: Path,
    done: Callable[[], float] | None,
    sink: SinkFactory | None = None,
) -> RunSummary:
    """Run recorded pulses and INS samples through a new pipeline on a virtual clock.

    The radar is read a block (``imaging.block_pulses``) at a time; INS samples are read
    ahead until they cover the newest pulse plus the longest bridged gap, so the aligner
    sees what it would have seen live, as fast as the CPU allows. The aligner's clock is
    the newest pulse time. The first pulses are held for the first reference track's
    course (``mocomp.heading_window_s``, which a live run cannot wait for).

    Parameters
    ----------
    done : callable or None
        Share of the input read so far, for a progress bar on stderr (None: no bar).
    sink : SinkFactory, optional
        Imaging deferred: no tiles are recorded (:class:`Pipeline`).

    Raises
    ------
    DataFileError
        When no pulse was focused (the store is still closed complete): the message
        gives the time span each stream covered and what was rejected, and how often.
    """
    cfg = replace(cfg, imaging=replace(cfg.imaging, live_degrade=False))  # full image
    lead_ns = round(cfg.ins.max_gap_s * 1e9)
    ins_span = _Span()
    with open_recorder(cfg, out) as recorder:
        pipe = Pipeline(cfg, recorder, Counters(), sink, hold_course=True)
        record_ins_format(recorder, ins)
        ahead: list[Sample] = []  # read from the log, not yet due (a poll may return seconds)
        while not radar.eof:
            pipe.read_radar(radar, 0.0, cfg.imaging.block_pulses)
            now = pipe.now_ns(live=False)
            horizon = None if now is None else now + lead_ns
            while not ins.eof and (horizon is None or not ahead or ahead[-1].t_gps_ns < horizon):
                ahead += ins.poll(0.0)
                pipe.add_ins_raw(ins.take_raw(), None)
            due = len(ahead) if horizon is None else sum(s.t_gps_ns <= horizon for s in ahead)
            pipe.add_nav(ahead[:due], None)
            ins_span.add(*(s.t_gps_ns for s in ahead[:due]))
            del ahead[:due]
            pipe.process(now)
            if done is not None:
                _progress(done())
        summary = pipe.finish()
    if done is not None:
        _progress(1.0, end=True)
    if summary.pulses_processed == 0:
        raise DataFileError(_nothing_focused(out, pipe, radar, ins, ins_span))
    return summary


@dataclass
class _Span:
    """First and last time (GPS ns) of what a stream gave, and how many items."""

    first: int | None = None
    last: int | None = None
    n: int = 0

    def add(self, *t_ns: int | None) -> None:
        """Count items at these times (GPS ns; None is skipped)."""
        for t in t_ns:
            if t is not None:
                self.first = t if self.first is None else min(self.first, t)
                self.last = t if self.last is None else max(self.last, t)
                self.n += 1

    def text(self) -> str:
        """`` over GPS a .. b s``, or nothing when the stream gave nothing."""
        if self.first is None or self.last is None:
            return ""
        return f" over GPS {self.first * 1e-9:.3f} .. {self.last * 1e-9:.3f} s"


def _nothing_focused(
    out: Path, pipe: Pipeline, radar: RadarSource | StorePulses, ins: Source, ins_span: _Span
) -> str:
    """Why a replay focused nothing: what each stream gave, over which time, what was refused."""
    store = open_store(out)
    n = store.committed("pulses")
    radar_span = _Span()
    if n:
        radar_span.add(*store.read("pulses", ["t_ns"], 0, 1)["t_ns"].tolist())
        radar_span.add(*store.read("pulses", ["t_ns"], n - 1, n)["t_ns"].tolist())
    radar_counts, streams = {}, ""
    if isinstance(radar, RadarSource):
        radar_counts = radar.decoder.counters.snapshot()
        skipped = sorted(radar.decoder.skipped_streams)
        if skipped:
            streams = (
                f"; skipped VITA streams {', '.join(str(s) for s in skipped)} "
                f"(radar.stream_id = {radar.decoder.stream_id} is decoded; set it to one of these)"
            )
    return (
        f"replay focused no pulse: radar {n} pulses{radar_span.text()}"
        f"{_nonzero(radar_counts)}{streams}; INS {ins_span.n} samples{ins_span.text()}"
        f"{_nonzero(ins.counters.snapshot())}{_nonzero(pipe.nav.counts(), 'refused')}; "
        f"{pipe.summary.pulses_nav_flagged} pulses without navigation (INS gap "
        f"{pipe.aligner.nav_gap}, beyond the INS {pipe.aligner.nav_timeout}); store {out}"
    )


def _nonzero(counts: Mapping[str, float], what: str = "") -> str:
    """`` (WHAT: name n, ...)``: the non-zero counts other than ``bytes``, ``frames`` and
    ``*accepted``, those two alongside; nothing when none is non-zero."""
    bad = {k for k, v in counts.items() if v and k not in ("bytes", "frames")}
    bad -= {k for k in bad if k.endswith("accepted")}
    if not bad:
        return ""
    shown = {k: v for k, v in counts.items() if v and (k in bad or k in ("bytes", "frames"))}
    items = ", ".join(f"{k} {v:g}" for k, v in shown.items())
    return f" ({what + ': ' if what else ''}{items})"


def _progress(fraction: float, end: bool = False) -> None:
    width = 40
    done = round(width * min(max(fraction, 0.0), 1.0))
    sys.stderr.write(f"\rreplay [{'#' * done}{'.' * (width - done)}] {100 * fraction:5.1f} %")
    if end:
        sys.stderr.write("\n")
    sys.stderr.flush()
