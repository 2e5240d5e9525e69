"""The radar as a MAVLink camera component (camera protocol v2) for the ground station.

On its own link (``camera.link``, a pymavlink connection string that reaches the ground
station: a mavlink-router endpoint, or an autopilot port that routes MAVLink) the daemon
appears as a component of type ``MAV_TYPE_CAMERA`` with the configured system and
component ids (``camera.system_id``, ``camera.component_id``):

- HEARTBEAT once a second; ``system_status`` says the state: ``MAV_STATE_ACTIVE`` while
  capturing, ``MAV_STATE_STANDBY`` while idle, ``MAV_STATE_CRITICAL`` while a fault of
  severity error or worse stands.
- MAV_CMD_REQUEST_MESSAGE (and the older MAV_CMD_REQUEST_CAMERA_INFORMATION,
  MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS) for CAMERA_INFORMATION (vendor ``sarmoco``,
  ``camera.model``, capability flags: image and video capture) and
  CAMERA_CAPTURE_STATUS, acknowledged with COMMAND_ACK.
- MAV_CMD_IMAGE_START_CAPTURE / MAV_CMD_VIDEO_START_CAPTURE start the capture,
  MAV_CMD_IMAGE_STOP_CAPTURE / MAV_CMD_VIDEO_STOP_CAPTURE stop it (the daemon keeps
  running: outside a capture the live run lets the pulses go, see
  :mod:`sarmoco.daemon.runner`). MAV_CMD_IMAGE_START_CAPTURE for a single image
  (``param3`` = 1, what a distance trigger sends) is answered ``MAV_RESULT_UNSUPPORTED``:
  a strip has no snapshot, and a capture it started would never be stopped.
  MAV_CMD_DO_SET_CAM_TRIGG_DIST (a survey mission's camera trigger distance) starts the
  capture for a distance (``param1``, m) above 0 and stops it for 0, as for a video
  payload; a distance that is negative or not a number is answered
  ``MAV_RESULT_DENIED`` and changes nothing.
  Commands are taken only from ``camera.command_system_ids``; a refused one is
  answered ``MAV_RESULT_DENIED``, counted (``camera_commands_refused``) and logged with
  its sender. With ``camera.signing_key_hex`` only signed packets are taken (MAVLink 2
  signing); the others are dropped unanswered and counted
  (``camera_unsigned_rejected``). Other commands addressed to the component are answered
  ``MAV_RESULT_UNSUPPORTED``.
- STATUSTEXT for each fault the operator must act on (:func:`operator_faults`): when it
  appears, again every ``camera.statustext_interval_s`` while it lasts, and once at
  ``MAV_SEVERITY_INFO`` when it clears.
- CAMERA_IMAGE_CAPTURED for each image product the run stored (a focused tile,
  :class:`Product`), within a second of its recording and for the last ones when the
  component stops; again on MAV_CMD_REQUEST_MESSAGE with its index in ``param2`` (how a
  ground station lists the images it missed; MAV_CMD_REQUEST_CAMERA_IMAGE_CAPTURE with it
  in ``param1`` likewise). CAMERA_CAPTURE_STATUS counts them (``image_count``).
- STORAGE_INFORMATION (on MAV_CMD_REQUEST_MESSAGE or MAV_CMD_REQUEST_STORAGE_INFORMATION):
  one storage, ready, the free space of the store's file system.
- MISSION_CURRENT from a system whose commands are taken (the autopilot) names the
  mission item a start capture belongs to (a survey leg's item: the store of a strip is
  named by it).
- STATUSTEXT for what the daemon tells the operator besides faults (:meth:`CameraComponent.notify`:
  a strip stored).

Everything runs on one thread of its own (:meth:`CameraComponent.start`); a malformed
or hostile message is counted (``camera_bad_messages``) and never ends it.
"""

from __future__ import annotations

import bisect
import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.daemon.config import CameraConfig
from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.daemon.status import Counters
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.drivers.samples import Sample, VelocitySample
from sarmoco.errors import ConfigError, DriverError
from sarmoco.store.schema import tile_name

log = logging.getLogger(__name__)

VENDOR = "sarmoco"
"""CAMERA_INFORMATION vendor name."""

HEARTBEAT_PERIOD_S = 1.0
"""Interval between HEARTBEATs and between looks at the faults, s."""

POLL_S = 0.05
"""Receive timeout of the component's loop, s."""

RADAR_SILENT_S = 2.0
"""The radar counts as silent when its last pulse is older than this (host clock), s."""

FOCUS_BEHIND_S = 10.0
"""Focusing counts as behind when it lags the recording by more than this, s."""

STATUSTEXT_CHARS = 50
"""Characters of one STATUSTEXT (longer texts are cut)."""

CAPABILITIES = (
    mav.CAMERA_CAP_FLAGS_CAPTURE_VIDEO
    | mav.CAMERA_CAP_FLAGS_CAPTURE_IMAGE
    | mav.CAMERA_CAP_FLAGS_HAS_MODES
)
"""CAMERA_INFORMATION capability flags: a strip is a video, a focused tile an image."""

URL_BYTES = 205
"""Bytes of CAMERA_IMAGE_CAPTURED's ``file_url`` (longer URLs are cut)."""

UNKNOWN_DEG_E7 = 2**31 - 1
"""CAMERA_IMAGE_CAPTURED latitude and longitude when no absolute position is known
(INT32_MAX, the value MAVLink's position messages give to an unknown one)."""

FIX_NEAR_S = 1.0
"""A product's position is the INS's absolute fix nearest its middle time, if within this, s."""

FIXES_KEPT = 100_000
"""Absolute fixes :class:`ProductLog` keeps (the older half goes when it has more)."""

SEVERITY_INFO = mav.MAV_SEVERITY_INFO
"""STATUSTEXT severity of what the operator is told for information (a strip stored)."""

SEVERITY_WARNING = mav.MAV_SEVERITY_WARNING
"""STATUSTEXT severity of what the operator should look at (a strip without pulses)."""

START = {mav.MAV_CMD_IMAGE_START_CAPTURE, mav.MAV_CMD_VIDEO_START_CAPTURE}
STOP = {mav.MAV_CMD_IMAGE_STOP_CAPTURE, mav.MAV_CMD_VIDEO_STOP_CAPTURE}


class Fault(NamedTuple):
    """A fault the operator must act on."""

    severity: int
    """MAV_SEVERITY (0 emergency … 7 debug)."""
    text: str
    """What the ground station shows (at most :data:`STATUSTEXT_CHARS` characters)."""


def operator_faults(
    components: Mapping[str, Mapping[str, Any]],
    gauges: Mapping[str, float],
    disk_free_fraction: float | None,
    disk_low_fraction: float,
) -> dict[str, Fault]:
    """The faults the operator must act on, by name, from the daemon's health and gauges.

    Parameters
    ----------
    components : mapping
        :meth:`~sarmoco.daemon.status.Health.components` (``ok`` and ``detail`` each).
    gauges : mapping
        The gauges of :meth:`~sarmoco.daemon.status.Counters.snapshot`:
        ``ins_age_seconds``, ``radar_age_seconds``, ``focus_lag_seconds`` (s).
    disk_free_fraction : float or None
        Free share of the store's file system (None: unknown).
    disk_low_fraction : float
        Free share below which the disk is nearly full; below a fifth of it, full.

    Returns
    -------
    dict of str to Fault
        ``ins``, ``links``, ``radar``, ``disk``, ``processing``, ``behind``: those that stand.
    """
    out: dict[str, Fault] = {}
    ins = components.get("ins")
    if ins is not None and not ins["ok"]:
        age = gauges.get("ins_age_seconds", math.inf)
        text = "no INS data" if math.isinf(age) else f"INS stale, {age:.1f} s old"
        out["ins"] = Fault(mav.MAV_SEVERITY_CRITICAL, f"SAR: {text}")
    links = components.get("links")
    if links is not None and not links["ok"]:
        out["links"] = Fault(mav.MAV_SEVERITY_ERROR, f"SAR link down: {links['detail']}")
    radar_age = gauges.get("radar_age_seconds", 0.0)
    if math.isfinite(radar_age) and radar_age > RADAR_SILENT_S:
        out["radar"] = Fault(mav.MAV_SEVERITY_ERROR, f"SAR: radar silent {radar_age:.0f} s")
    if disk_free_fraction is not None and disk_free_fraction < disk_low_fraction:
        full = disk_free_fraction < disk_low_fraction / 5
        state = "full" if full else "nearly full"
        out["disk"] = Fault(
            mav.MAV_SEVERITY_CRITICAL if full else mav.MAV_SEVERITY_WARNING,
            f"SAR: disk {state}, {100 * disk_free_fraction:.1f} % free",
        )
    processing = components.get("processing")
    if processing is not None and not processing["ok"]:
        out["processing"] = Fault(mav.MAV_SEVERITY_ERROR, f"SAR: {processing['detail']}")
    lag = gauges.get("focus_lag_seconds", 0.0)
    if math.isfinite(lag) and lag > FOCUS_BEHIND_S:
        out["behind"] = Fault(mav.MAV_SEVERITY_WARNING, f"SAR: focusing {lag:.0f} s behind")
    return {k: Fault(f.severity, f.text[:STATUSTEXT_CHARS]) for k, f in out.items()}


class Product(NamedTuple):
    """One image product the run stored (a focused tile, or a strip's whole store), as
    CAMERA_IMAGE_CAPTURED announces it.

    Attributes
    ----------
    image_index : int
        Its index among the products of the daemon's life, in the order they were stored
        (with one store, a tile's is its index in the store, ``images/tile_NNNNNN``).
    time_utc_us : int
        The middle of the pulses that formed it, µs since 1970 (UTC).
    lat_lon_alt : tuple of 3 float or None
        Where the antenna was then: latitude, longitude (deg, WGS 84) and altitude (m, as
        the INS gives it); None without an absolute position from the INS.
    height_m : float
        The antenna's height above the ground the image is formed on, m
        (``relative_alt``).
    url : str
        Where it is: the store's tile group, or the strip's store (``file://...``).
    """

    image_index: int
    time_utc_us: int
    lat_lon_alt: tuple[float, float, float] | None
    height_m: float
    url: str


class ProductLog:
    """The image products the daemon stored, each with where the antenna was: what the
    camera component announces. The focused tiles of every store, and each strip's store
    once closed (:meth:`add_strip`), in the order they were stored.

    Parameters
    ----------
    feed : LiveFeed
        The feed the recorders publish each stored tile to.
    store : Path
        The store the recorder writes to first (:meth:`open_store` for the next).
    height_m : float
        The antenna's height above the imaged ground (``geometry.height_m``), m.
    gps_minus_utc_s : int
        GPS - UTC (``ins.gps_minus_utc_s``), s.
    """

    def __init__(self, feed: LiveFeed, store: Path, height_m: float, gps_minus_utc_s: int) -> None:
        self._feed = feed
        self._url = store.resolve().as_uri()
        self._tiles_seen = 0
        """Tiles of the feed made products so far."""
        self._made_lock = threading.Lock()
        """Serialises the camera's thread and the run's opening and closing of stores."""
        self._height_m = height_m
        self._leap_s = gps_minus_utc_s
        self._lock = threading.Lock()
        self._fix_t: list[int] = []
        self._fix_lla: list[tuple[float, float, float]] = []
        self._made: list[Product] = []

    def add_fixes(self, samples: Sequence[Sample]) -> None:
        """Keep the absolute positions among INS samples (from the INS reader's thread)."""
        fixes = [
            (s.t_gps_ns, s.lat_lon_alt)
            for s in samples
            if isinstance(s, VelocitySample) and s.lat_lon_alt is not None
        ]
        if not fixes:
            return
        with self._lock:
            for t, lla in fixes:
                if self._fix_t and t <= self._fix_t[-1]:
                    continue  # out of order or repeated: the history stays sorted
                self._fix_t.append(t)
                self._fix_lla.append(lla)
            if len(self._fix_t) > FIXES_KEPT:
                del self._fix_t[: FIXES_KEPT // 2], self._fix_lla[: FIXES_KEPT // 2]

    def _position(self, t_ns: int) -> tuple[float, float, float] | None:
        with self._lock:
            k = bisect.bisect_left(self._fix_t, t_ns)
            near = [j for j in (k - 1, k) if 0 <= j < len(self._fix_t)]
            if not near:
                return None
            j = min(near, key=lambda j: abs(self._fix_t[j] - t_ns))
            return self._fix_lla[j] if abs(self._fix_t[j] - t_ns) <= FIX_NEAR_S * 1e9 else None

    def products(self) -> list[Product]:
        """Every product stored so far, in the order stored (a list that only grows)."""
        with self._made_lock:
            self._take_tiles()
            return self._made

    def open_store(self, store: Path) -> None:
        """The tiles the feed gives from now on are those of ``store`` (a strip's)."""
        with self._made_lock:
            self._take_tiles()
            self._url = store.resolve().as_uri()

    def add_strip(self, store: Path, t0_ns: int, t1_ns: int) -> Product:
        """A strip's store was closed, its pulses from ``t0_ns`` to ``t1_ns`` (GPS ns): its
        product (after the tiles stored before it), placed at the middle of the strip."""
        with self._made_lock:
            self._take_tiles()
            strip = self._product((t0_ns + t1_ns) // 2, store.resolve().as_uri())
            self._made.append(strip)
            return strip

    def _take_tiles(self) -> None:
        """Make products of the tiles the feed has given since the last look (lock held)."""
        spans = self._feed.stored_tiles(self._tiles_seen)
        self._tiles_seen += len(spans)
        for index, t0, t1 in spans:
            url = f"{self._url}/images/{tile_name(index)}"
            self._made.append(self._product((t0 + t1) // 2, url))

    def _product(self, mid_ns: int, url: str) -> Product:
        """The next product: formed around ``mid_ns`` (GPS ns), at ``url``."""
        utc_us = gps_ns_to_unix_ns(mid_ns, self._leap_s) // 1000
        return Product(len(self._made), utc_us, self._position(mid_ns), self._height_m, url)


class CameraComponent:
    """The MAVLink camera component on ``cfg.link``.

    Parameters
    ----------
    cfg : CameraConfig
        The ``camera`` section.
    model : str
        CAMERA_INFORMATION model name (at most 32 bytes of UTF-8 are sent).
    faults : callable
        Returns the faults that stand now (:func:`operator_faults`); called once a second
        on the component's thread.
    free_bytes : callable
        Free space for the store, bytes (None: unknown): CAMERA_CAPTURE_STATUS
        ``available_capacity``.
    on_capture : callable
        Called with True when a start capture command is taken, False for a stop, and the
        mission item the autopilot last reported current (MISSION_CURRENT ``seq``; None
        before one), on the component's thread, before the command is acknowledged.
    counters : Counters
        Where ``camera_commands``, ``camera_commands_refused`` and ``camera_bad_messages``
        are counted.
    products : callable, optional
        Returns the image products stored so far, in store order (a list that only
        grows); called once a second on the component's thread. Default: none.

    Raises
    ------
    DriverError
        If the link cannot be opened.
    """

    def __init__(
        self,
        cfg: CameraConfig,
        model: str,
        faults: Callable[[], Mapping[str, Fault]],
        free_bytes: Callable[[], int | None],
        on_capture: Callable[[bool, int | None], None],
        counters: Counters,
        products: Callable[[], Sequence[Product]] = tuple,
    ) -> None:
        self.cfg = cfg
        self.model = model
        self._faults = faults
        self._free_bytes = free_bytes
        self._on_capture = on_capture
        self._products = products
        self._announced = 0
        """Products announced so far (the first ones of :attr:`_products`)."""
        self.counters = counters
        self.capturing = cfg.capture_at_start
        """Whether the component captures now."""
        self._capture_since = time.monotonic()
        self._boot = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._standing: dict[str, Fault] = {}
        self._sent_at: dict[str, float] = {}
        self._notices: deque[Fault] = deque()
        """STATUSTEXTs to send besides faults (:meth:`notify`), oldest first."""
        self.mission_item: int | None = None
        """The mission item the autopilot last reported current (None: none yet)."""
        for name in ("camera_commands", "camera_commands_refused", "camera_bad_messages"):
            counters.inc(name, 0)
        key = signing_key(cfg.signing_key_hex)  # before a socket is opened
        try:
            self._conn = mavutil.mavlink_connection(
                cfg.link, source_system=cfg.system_id, source_component=cfg.component_id,
                dialect="ardupilotmega",
            )  # fmt: skip
        except (OSError, ValueError) as exc:
            raise DriverError(f"camera.link {cfg.link}: cannot open: {exc}") from exc
        if key is not None:
            self._conn.setup_signing(
                key, sign_outgoing=True, allow_unsigned_callback=lambda _m, _id: False
            )
            signing = self._conn.mav.signing
            counters.add_source("camera", lambda: {"unsigned_rejected": signing.reject_count})

    # -- life -----------------------------------------------------------------------------

    def start(self) -> CameraComponent:
        """Start the component's thread; returns self."""
        self._thread = threading.Thread(target=self._run, name="camera", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the link."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        try:
            self._announce_products()  # those stored since the last heartbeat
            while self._notices:
                self._statustext(self._notices.popleft())
        except OSError as exc:
            log.warning("camera link error", extra={"link": self.cfg.link, "error": str(exc)})
        try:
            self._conn.close()
        except OSError as exc:
            log.debug("camera.link %s: close: %s", self.cfg.link, exc)

    def notify(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT (MAV_SEVERITY ``severity``) within :data:`POLL_S`; any thread."""
        self._notices.append(Fault(severity, text))

    def _run(self) -> None:
        next_beat = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                if now >= next_beat:
                    next_beat = now + HEARTBEAT_PERIOD_S
                    self._heartbeat()
                    self._announce(now)
                    self._announce_products()
                while self._notices:
                    self._statustext(self._notices.popleft())
                self._receive()
            except OSError as exc:  # the link's socket or port went away: try again
                log.warning("camera link error", extra={"link": self.cfg.link, "error": str(exc)})
                self._stop.wait(HEARTBEAT_PERIOD_S)

    def _receive(self) -> None:
        """Handle what arrives within :data:`POLL_S`."""
        try:
            msg = self._conn.recv_match(blocking=True, timeout=POLL_S)
        except ValueError:  # pymavlink choked on the bytes
            self.counters.inc("camera_bad_messages")
            return
        while msg is not None:
            kind = msg.get_type()
            if kind == "BAD_DATA" or kind.startswith("UNKNOWN_"):
                self.counters.inc("camera_bad_messages")
            elif kind in ("COMMAND_LONG", "COMMAND_INT"):
                self._command(msg)
            elif kind == "MISSION_CURRENT" and msg.get_srcSystem() in self.cfg.command_system_ids:
                self.mission_item = int(msg.seq)
            try:
                msg = self._conn.recv_match(blocking=False)
            except ValueError:
                self.counters.inc("camera_bad_messages")
                return

    # -- what the component sends ---------------------------------------------------------

    def _boot_ms(self) -> int:
        return round((time.monotonic() - self._boot) * 1000) & 0xFFFFFFFF

    def _heartbeat(self) -> None:
        if any(f.severity <= mav.MAV_SEVERITY_ERROR for f in self._standing.values()):
            state = mav.MAV_STATE_CRITICAL
        else:
            state = mav.MAV_STATE_ACTIVE if self.capturing else mav.MAV_STATE_STANDBY
        self._conn.mav.heartbeat_send(mav.MAV_TYPE_CAMERA, mav.MAV_AUTOPILOT_INVALID, 0, 0, state)

    def _announce(self, now: float) -> None:
        """STATUSTEXT for faults that appeared, repeats of those that last, and clearings."""
        faults = dict(self._faults())
        for name, fault in faults.items():
            last = self._sent_at.get(name)
            if last is None or now - last >= self.cfg.statustext_interval_s:
                self._statustext(fault)
                self._sent_at[name] = now
        for name in set(self._standing) - set(faults):
            self._statustext(Fault(mav.MAV_SEVERITY_INFO, f"cleared: {self._standing[name].text}"))
            self._sent_at.pop(name, None)
        self._standing = faults

    def _statustext(self, fault: Fault) -> None:
        log.info("statustext", extra={"severity": fault.severity, "text": fault.text})
        self._conn.mav.statustext_send(fault.severity, fault.text[:STATUSTEXT_CHARS].encode())

    def _announce_products(self) -> None:
        """CAMERA_IMAGE_CAPTURED for each product stored since the last announcement."""
        new = self._products()[self._announced :]
        for product in new:
            self._image_captured(product)
        self._announced += len(new)

    def _image_captured(self, p: Product) -> None:
        if p.lat_lon_alt is None:
            lat = lon = UNKNOWN_DEG_E7
            alt_mm = 0
        else:
            lat, lon = (round(v * 1e7) for v in p.lat_lon_alt[:2])
            alt_mm = round(p.lat_lon_alt[2] * 1000)
        self._conn.mav.camera_image_captured_send(
            self._boot_ms(), p.time_utc_us, 0, lat, lon, alt_mm, round(p.height_m * 1000),
            [math.nan] * 4, p.image_index, 1, p.url.encode()[:URL_BYTES],
        )  # fmt: skip

    def _information(self) -> None:
        self._conn.mav.camera_information_send(
            self._boot_ms(), _text32(VENDOR), _text32(self.model), 0, math.nan, math.nan,
            math.nan, 0, 0, 0, CAPABILITIES, 0, b"",
        )  # fmt: skip

    def _storage(self) -> None:
        """STORAGE_INFORMATION: one storage, ready, its free space (MiB) that of the store."""
        free = self._free_bytes()
        self._conn.mav.storage_information_send(
            self._boot_ms(), 1, 1, mav.STORAGE_STATUS_READY, math.nan, math.nan,
            math.nan if free is None else free / 2**20, math.nan, math.nan,
            mav.STORAGE_TYPE_OTHER, b"sarmoco store",
        )  # fmt: skip

    def _capture_status(self) -> None:
        """CAMERA_CAPTURE_STATUS, then CAMERA_IMAGE_CAPTURED of the newest product (if any):
        a ground station that connected after the products were announced (MAVSDK) learns
        the newest index and asks for those before it by index."""
        on = int(self.capturing)
        recording_ms = round((time.monotonic() - self._capture_since) * 1000) if on else 0
        free = self._free_bytes()
        products = self._products()
        self._conn.mav.camera_capture_status_send(
            self._boot_ms(), on, on, 0.0, recording_ms & 0xFFFFFFFF,
            math.nan if free is None else free / 2**20, len(products),
        )  # fmt: skip
        if products:  # a late ground station learns the newest; MAVSDK then asks for the rest
            self._image_captured(products[-1])

    # -- commands -------------------------------------------------------------------------

    def _command(self, msg: Any) -> None:
        """Take, refuse or answer as unsupported one COMMAND_LONG or COMMAND_INT for us."""
        if msg.target_system not in (0, self.cfg.system_id) or msg.target_component not in (
            0,
            self.cfg.component_id,
        ):
            return
        cmd, sender = msg.command, (msg.get_srcSystem(), msg.get_srcComponent())
        if sender[0] not in self.cfg.command_system_ids:
            self.counters.inc("camera_commands_refused")
            who = {"sender_system": sender[0], "sender_component": sender[1]}
            log.warning("camera command refused", extra={"command": cmd, **who})
            self._ack(cmd, mav.MAV_RESULT_DENIED, sender)
            return
        self.counters.inc("camera_commands")
        answer: Callable[[], None] | None = None
        if cmd == mav.MAV_CMD_REQUEST_MESSAGE:
            answer = {
                mav.MAVLINK_MSG_ID_CAMERA_INFORMATION: self._information,
                mav.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS: self._capture_status,
                mav.MAVLINK_MSG_ID_CAMERA_IMAGE_CAPTURED: self._stored(_whole(msg.param2)),
                mav.MAVLINK_MSG_ID_STORAGE_INFORMATION: self._storage,
            }.get(_whole(msg.param1))
        elif cmd == mav.MAV_CMD_REQUEST_CAMERA_INFORMATION:
            answer = self._information
        elif cmd == mav.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS:
            answer = self._capture_status
        elif cmd == mav.MAV_CMD_REQUEST_CAMERA_IMAGE_CAPTURE:
            answer = self._stored(_whole(msg.param1))
        elif cmd == mav.MAV_CMD_REQUEST_STORAGE_INFORMATION:
            answer = self._storage
        elif cmd == mav.MAV_CMD_IMAGE_START_CAPTURE and _whole(msg.param3) == 1:
            answer = None  # a single still (a distance trigger): a strip has no snapshot
        elif cmd in START or cmd in STOP:
            self._set_capture(cmd in START, sender)
            answer = self._capture_status
        elif cmd == mav.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
            if not math.isfinite(msg.param1) or msg.param1 < 0:
                self._ack(cmd, mav.MAV_RESULT_DENIED, sender)
                return
            self._set_capture(msg.param1 > 0, sender)
            answer = self._capture_status
        result = mav.MAV_RESULT_UNSUPPORTED if answer is None else mav.MAV_RESULT_ACCEPTED
        self._ack(cmd, result, sender)
        if answer is not None:
            answer()

    def _stored(self, index: int | None) -> Callable[[], None] | None:
        """What sends CAMERA_IMAGE_CAPTURED of stored product ``index`` (None: no such one)."""
        products = self._products()
        if index is None or not 0 <= index < len(products):
            return None
        product = products[index]
        return lambda: self._image_captured(product)

    def _set_capture(self, on: bool, sender: tuple[int, int]) -> None:
        if on != self.capturing:
            self._on_capture(on, self.mission_item)
            self.capturing = on
            self._capture_since = time.monotonic()
        log.info("camera capture", extra={"capturing": on, "sender_system": sender[0],
                                          "sender_component": sender[1],
                                          "mission_item": self.mission_item})  # fmt: skip

    def _ack(self, cmd: int, result: int, sender: tuple[int, int]) -> None:
        self._conn.mav.command_ack_send(cmd, result, 0, 0, sender[0], sender[1])


def signing_key(text: str) -> bytes | None:
    """The 32-byte MAVLink 2 signing key of ``camera.signing_key_hex`` (None: empty).

    Raises
    ------
    ConfigError
        If the text is not 64 hexadecimal digits.
    """
    if not text:
        return None
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != 32:
        raise ConfigError("camera.signing_key_hex: not 64 hexadecimal digits (32 bytes)")
    return key


def _whole(param: float) -> int | None:
    """A command parameter as a whole number (None: NaN or infinite, as unused ones are)."""
    return round(param) if math.isfinite(param) else None


def _text32(text: str) -> list[int]:
    """``text`` as a MAVLink ``uint8_t[32]`` (UTF-8, cut at 32 bytes, zero-padded)."""
    raw = text.encode()[:32]
    return [*raw, *bytes(32 - len(raw))]
