"""The MAVLink camera component against real ground-station clients on 127.0.0.1.

A pymavlink connection (``udpin``, system 255, as QGroundControl or MAVProxy listens)
plays the ground station: it discovers the component by its HEARTBEAT, requests
CAMERA_INFORMATION and CAMERA_CAPTURE_STATUS, starts and stops capture, is refused
from a system id that is not configured, and hears the STATUSTEXT of a fault set on the
daemon's real :class:`~sarmoco.daemon.status.Health`. MAVSDK (its C++ core, through the
``mavsdk`` package, when installed) discovers the component as a camera.
"""

from __future__ import annotations

import logging
import math
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.daemon.camera import (
    UNKNOWN_DEG_E7,
    CameraComponent,
    Fault,
    Product,
    ProductLog,
    operator_faults,
)
from sarmoco.daemon.config import CameraConfig
from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.daemon.status import Counters, Health
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.drivers.samples import Validity, VelocitySample
from sarmoco.errors import ConfigError
from sarmoco.processing.types import Image

WAIT_S = 5.0
"""Longest wait for one answer of the component, s."""


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Bench:
    """The component, its daemon-side state and a pymavlink ground station."""

    camera: CameraComponent
    gcs: Any
    health: Health
    counters: Counters
    gauges: dict[str, float]
    captures: list[bool] = field(default_factory=list)

    def recv(self, kind: str, check: Callable[[Any], bool] = lambda m: True) -> Any:
        """The next ``kind`` message from the component that passes ``check``."""
        deadline = time.monotonic() + WAIT_S
        while (left := deadline - time.monotonic()) > 0:
            msg = self.gcs.recv_match(type=kind, blocking=True, timeout=left)
            if msg is not None and msg.get_srcComponent() == self.camera.cfg.component_id:
                if check(msg):
                    return msg
        raise AssertionError(f"no {kind} from the camera within {WAIT_S} s")

    def command(self, cmd: int, *params: float) -> Any:
        """Send COMMAND_LONG to the component; return its COMMAND_ACK."""
        p = [*params, 0, 0, 0, 0, 0, 0, 0][:7]
        cfg = self.camera.cfg
        self.gcs.mav.command_long_send(cfg.system_id, cfg.component_id, cmd, 0, *p)
        return self.recv("COMMAND_ACK", lambda m: m.command == cmd)


def start_bench(cfg: CameraConfig, products: Callable[[], list[Product]] = list) -> Bench:
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
        dialect="ardupilotmega",
    )  # fmt: skip
    health, counters, gauges = Health(), Counters(), {"ins_age_seconds": 0.1}
    captures: list[bool] = []
    camera = CameraComponent(
        replace(cfg, link=f"udpout:127.0.0.1:{port}"), "SAR 15 GHz",
        lambda: operator_faults(health.components(), gauges, 0.5, cfg.disk_low_fraction),
        lambda: 2**30, lambda on, _item: captures.append(on), counters, products,
    ).start()  # fmt: skip
    b = Bench(camera, gcs, health, counters, gauges, captures)
    b.recv("HEARTBEAT")  # a udpin ground station answers the address it heard from
    return b


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = start_bench(CameraConfig(enabled=True, capture_at_start=False, statustext_interval_s=1.0))
    yield b
    b.camera.stop()
    b.gcs.close()


def test_ground_station_discovers_the_camera_and_reads_its_information(bench: Bench) -> None:
    beat = bench.recv("HEARTBEAT")
    assert beat.type == mav.MAV_TYPE_CAMERA
    assert beat.autopilot == mav.MAV_AUTOPILOT_INVALID
    assert beat.system_status == mav.MAV_STATE_STANDBY  # not capturing
    assert beat.get_srcSystem() == 1
    ack = bench.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_CAMERA_INFORMATION)
    assert ack.result == mav.MAV_RESULT_ACCEPTED
    assert (ack.target_system, ack.target_component) == (255, 190)
    info = bench.recv("CAMERA_INFORMATION")
    assert bytes(info.vendor_name).rstrip(b"\0") == b"sarmoco"
    assert bytes(info.model_name).rstrip(b"\0") == b"SAR 15 GHz"
    assert info.flags & mav.CAMERA_CAP_FLAGS_CAPTURE_VIDEO
    assert info.flags & mav.CAMERA_CAP_FLAGS_CAPTURE_IMAGE
    ack = bench.command(mav.MAV_CMD_DO_SET_ROI_NONE)
    assert ack.result == mav.MAV_RESULT_UNSUPPORTED


def test_a_single_image_trigger_is_unsupported_and_starts_nothing(bench: Bench) -> None:
    ack = bench.command(mav.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1)  # one image, as CAM_TRIGG_DIST
    assert ack.result == mav.MAV_RESULT_UNSUPPORTED
    assert bench.captures == [] and not bench.camera.capturing


@pytest.mark.parametrize(
    ("start", "stop"),
    [
        (mav.MAV_CMD_VIDEO_START_CAPTURE, mav.MAV_CMD_VIDEO_STOP_CAPTURE),
        (mav.MAV_CMD_IMAGE_START_CAPTURE, mav.MAV_CMD_IMAGE_STOP_CAPTURE),
    ],
)
def test_start_and_stop_capture(bench: Bench, start: int, stop: int) -> None:
    ack = bench.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS)
    assert ack.result == mav.MAV_RESULT_ACCEPTED
    assert bench.recv("CAMERA_CAPTURE_STATUS").video_status == 0
    assert bench.command(start).result == mav.MAV_RESULT_ACCEPTED
    assert bench.captures == [True]
    status = bench.recv("CAMERA_CAPTURE_STATUS")
    assert (status.video_status, status.image_status) == (1, 1)
    assert status.available_capacity == pytest.approx(1024.0)  # MiB
    assert bench.recv("HEARTBEAT").system_status == mav.MAV_STATE_ACTIVE
    assert bench.command(stop).result == mav.MAV_RESULT_ACCEPTED
    assert bench.captures == [True, False]
    assert bench.recv("CAMERA_CAPTURE_STATUS").video_status == 0
    assert bench.recv("HEARTBEAT").system_status == mav.MAV_STATE_STANDBY


def test_a_mission_trigger_distance_starts_and_stops_a_strip(bench: Bench) -> None:
    """DO_SET_CAM_TRIGG_DIST as a survey mission sends it: a distance above 0 starts the
    capture (a strip), 0 stops it; a negative or NaN distance is denied and changes nothing."""
    trigger = mav.MAV_CMD_DO_SET_CAM_TRIGG_DIST
    assert bench.command(trigger, 25.0).result == mav.MAV_RESULT_ACCEPTED
    assert bench.captures == [True] and bench.camera.capturing
    assert bench.recv("CAMERA_CAPTURE_STATUS").video_status == 1
    assert bench.recv("HEARTBEAT").system_status == mav.MAV_STATE_ACTIVE
    assert bench.command(trigger, 40.0).result == mav.MAV_RESULT_ACCEPTED  # a new distance
    assert bench.captures == [True]  # the strip goes on
    for bad in (-5.0, math.nan):
        assert bench.command(trigger, bad).result == mav.MAV_RESULT_DENIED
        assert bench.captures == [True] and bench.camera.capturing
    assert bench.command(trigger, 0.0).result == mav.MAV_RESULT_ACCEPTED
    assert bench.captures == [True, False] and not bench.camera.capturing
    assert bench.recv("CAMERA_CAPTURE_STATUS").video_status == 0


def test_commands_from_other_systems_are_refused_counted_and_logged(
    bench: Bench, caplog: pytest.LogCaptureFixture
) -> None:
    bench.gcs.mav.srcSystem = 42  # a second ground station, not configured
    with caplog.at_level(logging.WARNING, logger="sarmoco.daemon.camera"):
        ack = bench.command(mav.MAV_CMD_VIDEO_START_CAPTURE)
    assert ack.result == mav.MAV_RESULT_DENIED
    assert bench.captures == []
    assert not bench.camera.capturing
    assert bench.counters.snapshot()["counters"]["camera_commands_refused"] == 1
    refused = [r for r in caplog.records if r.getMessage() == "camera command refused"]
    assert [r.__dict__["sender_system"] for r in refused] == [42]


KEY = bytes(range(32))


def test_with_a_signing_key_only_signed_commands_are_taken() -> None:
    b = start_bench(CameraConfig(enabled=True, capture_at_start=False, signing_key_hex=KEY.hex()))
    try:
        b.gcs.mav.command_long_send(1, 100, mav.MAV_CMD_VIDEO_START_CAPTURE, 0, 0, 0, 0, 0, 0, 0, 0)
        with pytest.raises(AssertionError, match="no COMMAND_ACK"):
            b.recv("COMMAND_ACK")
        assert b.captures == []
        assert b.counters.snapshot()["counters"]["camera_unsigned_rejected"] >= 1
        b.gcs.setup_signing(KEY, sign_outgoing=True)
        assert b.command(mav.MAV_CMD_VIDEO_START_CAPTURE).result == mav.MAV_RESULT_ACCEPTED
        assert b.captures == [True]
    finally:
        b.camera.stop()
        b.gcs.close()


def test_signing_key_must_be_32_bytes() -> None:
    with pytest.raises(ConfigError, match=r"camera\.signing_key_hex"):
        start_bench(CameraConfig(enabled=True, signing_key_hex="abcd"))


def test_capture_at_start_captures_from_the_start() -> None:
    b = start_bench(CameraConfig(enabled=True))
    try:
        assert b.camera.capturing
        assert b.recv("HEARTBEAT").system_status == mav.MAV_STATE_ACTIVE
        assert b.command(mav.MAV_CMD_VIDEO_STOP_CAPTURE).result == mav.MAV_RESULT_ACCEPTED
        assert b.captures == [False]
    finally:
        b.camera.stop()
        b.gcs.close()


def test_an_ins_dropout_is_announced_repeated_at_its_interval_and_cleared(bench: Bench) -> None:
    bench.health.set("ins", True)
    bench.health.set("ins", False, "newest sample 3.00 s old")
    bench.gauges["ins_age_seconds"] = 3.0
    first = bench.recv("STATUSTEXT")
    t_first = time.monotonic()
    assert first.severity == mav.MAV_SEVERITY_CRITICAL
    assert first.text == "SAR: INS stale, 3.0 s old"
    assert bench.recv("HEARTBEAT").system_status == mav.MAV_STATE_CRITICAL
    again = bench.recv("STATUSTEXT")
    assert again.text == first.text
    assert time.monotonic() - t_first > 0.8  # statustext_interval_s = 1, beats at 1 s
    bench.health.set("ins", True)
    cleared = bench.recv("STATUSTEXT", lambda m: m.text.startswith("cleared"))
    assert cleared.severity == mav.MAV_SEVERITY_INFO


def test_garbage_and_nan_parameters_are_survived_and_the_component_answers_on(bench: Bench) -> None:
    camera_address = bench.camera._conn.port.getsockname()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for junk in (b"\xfd\x09\x00\x00\x00\x01\x01" + bytes(30), b"\xfe" * 40, bytes(300)):
            tx.sendto(junk, camera_address)
    nan, inf = math.nan, math.inf  # unused parameters are NaN; a hostile sender sends anything
    assert bench.command(mav.MAV_CMD_REQUEST_MESSAGE, nan).result == mav.MAV_RESULT_UNSUPPORTED
    assert bench.command(mav.MAV_CMD_IMAGE_START_CAPTURE, nan, nan, inf).result == (
        mav.MAV_RESULT_ACCEPTED
    )
    ack = bench.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_CAMERA_INFORMATION)
    assert ack.result == mav.MAV_RESULT_ACCEPTED
    assert bench.counters.snapshot()["counters"]["camera_bad_messages"] >= 1


def test_operator_faults_name_each_fault_with_its_severity() -> None:
    ok = {"ok": True, "detail": ""}
    assert operator_faults({"ins": ok, "links": ok, "processing": ok}, {}, 0.5, 0.05) == {}
    down = {
        "ins": {"ok": False, "detail": ""},
        "links": {"ok": False, "detail": "radar: peer closed the link"},
        "processing": {"ok": False, "detail": "store write refused"},
    }
    gauges = {"ins_age_seconds": math.inf, "radar_age_seconds": 4.2, "focus_lag_seconds": 12.0}
    faults = operator_faults(down, gauges, 0.004, 0.05)
    assert faults == {
        "ins": Fault(mav.MAV_SEVERITY_CRITICAL, "SAR: no INS data"),
        "links": Fault(mav.MAV_SEVERITY_ERROR, "SAR link down: radar: peer closed the link"),
        "radar": Fault(mav.MAV_SEVERITY_ERROR, "SAR: radar silent 4 s"),
        "disk": Fault(mav.MAV_SEVERITY_CRITICAL, "SAR: disk full, 0.4 % free"),
        "processing": Fault(mav.MAV_SEVERITY_ERROR, "SAR: store write refused"),
        "behind": Fault(mav.MAV_SEVERITY_WARNING, "SAR: focusing 12 s behind"),
    }
    nearly = operator_faults({}, {"radar_age_seconds": math.inf}, 0.03, 0.05)
    assert nearly == {"disk": Fault(mav.MAV_SEVERITY_WARNING, "SAR: disk nearly full, 3.0 % free")}


def test_mavsdk_discovers_the_camera_and_starts_and_stops_video() -> None:
    """MAVSDK's camera plugin (a ground station of system 245) finds the component by its
    HEARTBEAT, reads CAMERA_INFORMATION, and its start/stop video commands are taken."""
    from mavsdk import Configuration, Mavsdk
    from mavsdk.component_type import ComponentType
    from mavsdk.plugins.camera import Camera

    port = free_udp_port()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
    captures: list[bool] = []
    cfg = CameraConfig(enabled=True, link=f"udpout:127.0.0.1:{port}", capture_at_start=False)
    camera = CameraComponent(
        cfg, "SAR 15 GHz", dict, lambda: None, lambda on, _item: captures.append(on), Counters()
    ).start()
    try:
        deadline = time.monotonic() + WAIT_S
        systems: list[Any] = []
        while not systems and time.monotonic() < deadline:
            systems = [s for s in sdk.get_systems() if s.has_camera()]
            time.sleep(0.1)
        assert systems, "MAVSDK found no camera"
        plugin = Camera(systems[0])
        cameras: list[Any] = []
        while not cameras and time.monotonic() < deadline:
            cameras = plugin.camera_list().cameras
            time.sleep(0.1)
        assert [(c.component_id, c.vendor_name, c.model_name) for c in cameras] == [
            (100, "sarmoco", "SAR 15 GHz")
        ]
        plugin.start_video(100)
        assert captures == [True]
        plugin.stop_video(100)
        assert captures == [True, False]
    finally:
        camera.stop()
        sdk.destroy()


def test_each_stored_product_is_announced_once_and_again_on_request() -> None:
    """Each product the run stores is announced with CAMERA_IMAGE_CAPTURED within a
    heartbeat (index, UTC time, position in 1e-7 deg and mm, URL), unknown positions as
    INT32_MAX; MAV_CMD_REQUEST_MESSAGE with an index sends it again (how a ground station
    lists what it missed), an index not stored is unsupported, CAMERA_CAPTURE_STATUS counts
    them and STORAGE_INFORMATION gives the free space (MiB)."""
    products: list[Product] = []
    b = start_bench(CameraConfig(enabled=True), lambda: products)
    try:
        products.append(Product(0, 1_700_000_000_123_456, (47.1234567, 8.7654321, 412.5), 100.0,
                                "file:///data/run.zarr/images/tile_000000"))  # fmt: skip
        first = b.recv("CAMERA_IMAGE_CAPTURED")
        assert (first.image_index, first.time_utc, first.capture_result) == (
            0, 1_700_000_000_123_456, 1)  # fmt: skip
        assert (first.lat, first.lon, first.alt, first.relative_alt) == (
            471234567, 87654321, 412500, 100000)  # fmt: skip
        assert first.file_url == "file:///data/run.zarr/images/tile_000000"
        products.append(Product(1, 1_700_000_001_000_000, None, 100.0, "file:///x"))
        second = b.recv("CAMERA_IMAGE_CAPTURED")
        assert second.image_index == 1 and second.lat == second.lon == UNKNOWN_DEG_E7
        time.sleep(1.5)  # a heartbeat more: nothing is announced twice
        assert b.gcs.recv_match(type="CAMERA_IMAGE_CAPTURED", blocking=False) is None
        request = mav.MAVLINK_MSG_ID_CAMERA_IMAGE_CAPTURED
        ack = b.command(mav.MAV_CMD_REQUEST_MESSAGE, request, 0)
        assert ack.result == mav.MAV_RESULT_ACCEPTED
        assert b.recv("CAMERA_IMAGE_CAPTURED").image_index == 0
        ack = b.command(mav.MAV_CMD_REQUEST_MESSAGE, request, 2)
        assert ack.result == mav.MAV_RESULT_UNSUPPORTED
        ack = b.command(mav.MAV_CMD_REQUEST_CAMERA_IMAGE_CAPTURE, 1)  # the older command
        assert ack.result == mav.MAV_RESULT_ACCEPTED
        assert b.recv("CAMERA_IMAGE_CAPTURED").image_index == 1
        ack = b.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_STORAGE_INFORMATION)
        assert ack.result == mav.MAV_RESULT_ACCEPTED
        storage = b.recv("STORAGE_INFORMATION")
        assert storage.status == mav.STORAGE_STATUS_READY and storage.available_capacity == 1024
        ack = b.command(mav.MAV_CMD_REQUEST_STORAGE_INFORMATION, 0)
        assert ack.result == mav.MAV_RESULT_ACCEPTED
        assert b.recv("STORAGE_INFORMATION").storage_count == 1
        b.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS)
        assert b.recv("CAMERA_CAPTURE_STATUS").image_count == 2
    finally:
        b.camera.stop()
        b.gcs.close()


def test_a_product_is_placed_at_the_absolute_fix_nearest_its_middle() -> None:
    """:class:`ProductLog`: each tile the recorder publishes becomes a product at the
    middle of its pulses, placed at the INS fix nearest that time (none beyond 1 s, none
    without a global position), its URL the store's tile group."""
    feed = LiveFeed()
    log_ = ProductLog(feed, Path("/data/run.zarr"), 100.0, 18)
    t0 = 1_400_000_000_000_000_000

    def fix(t_ns: int, lat: float | None) -> VelocitySample:
        lla = None if lat is None else (lat, 8.0, 400.0)
        return VelocitySample(t_ns, (0.0, 0.0, 0.0), Validity(0), "test", 0, lat_lon_alt=lla)

    log_.add_fixes([fix(t0, 47.0), fix(t0 + 10**8, 47.1), fix(t0 + 2 * 10**8, None),
                    fix(t0 + 3 * 10**9, 47.3)])  # fmt: skip
    image = Image(np.zeros((2, 2), np.complex64), np.arange(2.0), np.arange(2.0), "ground")
    feed.add_tile(0, image, t0, t0 + 2 * 10**8)  # middle t0 + 0.1 s: the second fix
    feed.add_tile(1, image, t0 + 10**9, t0 + 14 * 10**8)  # 1.8 s from the nearest
    p0, p1 = log_.products()
    assert p0.lat_lon_alt == (47.1, 8.0, 400.0) and p1.lat_lon_alt is None
    assert p0.time_utc_us == gps_ns_to_unix_ns(t0 + 10**8, 18) // 1000
    assert p1.url == "file:///data/run.zarr/images/tile_000001" and p1.image_index == 1
    assert log_.products() == [p0, p1]


def test_strips_and_their_tiles_are_numbered_in_the_order_stored_each_with_its_store() -> None:
    """:class:`ProductLog` across stores: the tiles of the first strip's store, that strip
    (its store's URL, placed at the fix nearest the middle of its pulses: the strip's
    centre), then the tiles of the next store, numbered one after the other."""
    feed = LiveFeed()
    first, second = Path("/data/leg-1.zarr"), Path("/data/leg-2.zarr")
    log_ = ProductLog(feed, first, 100.0, 18)
    t0 = 1_400_000_000_000_000_000
    fixes = [(t0 + k * 10**8, 47.0 + k / 100) for k in range(40)]
    log_.add_fixes([VelocitySample(t, (0.0, 0.0, 0.0), Validity(0), "test", 0,
                                   lat_lon_alt=(lat, 8.0, 400.0)) for t, lat in fixes])  # fmt: skip
    image = Image(np.zeros((2, 2), np.complex64), np.arange(2.0), np.arange(2.0), "ground")
    feed.add_tile(0, image, t0, t0 + 10**8)
    strip = log_.add_strip(first, t0, t0 + 2 * 10**9)  # the tile is taken before it
    log_.open_store(second)
    feed.add_tile(0, image, t0 + 3 * 10**9, t0 + 31 * 10**8)
    tile0, strip_, tile1 = log_.products()
    assert strip_ == strip and [p.image_index for p in (tile0, strip, tile1)] == [0, 1, 2]
    assert tile0.url == "file:///data/leg-1.zarr/images/tile_000000"
    assert strip.url == "file:///data/leg-1.zarr" and strip.lat_lon_alt == (47.1, 8.0, 400.0)
    assert strip.time_utc_us == gps_ns_to_unix_ns(t0 + 10**9, 18) // 1000
    assert tile1.url == "file:///data/leg-2.zarr/images/tile_000000"


def test_mavsdk_lists_the_products_stored_before_it_connected() -> None:
    """MAVSDK's camera plugin connects after five products were announced: with the newest
    one after CAMERA_CAPTURE_STATUS it asks for those before it by index, and
    ``list_photos`` (all) gives all five, with their URLs and positions."""
    from mavsdk import Configuration, Mavsdk
    from mavsdk.component_type import ComponentType
    from mavsdk.plugins.camera import Camera, CameraError, PhotosRange

    port = free_udp_port()
    products = [
        Product(k, 1_700_000_000_000_000 + k, (47.0, 8.0, 400.0), 100.0, f"file:///d/r.zarr/{k}")
        for k in range(5)
    ]
    cfg = CameraConfig(enabled=True, link=f"udpout:127.0.0.1:{port}", capture_at_start=False)
    camera = CameraComponent(
        cfg, "SAR 15 GHz", dict, lambda: None, lambda _on, _item: None, Counters(),
        lambda: products,
    ).start()  # fmt: skip
    time.sleep(1.5)  # announced before the ground station is there
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
    photos: list[Any] = []
    try:
        deadline = time.monotonic() + 4 * WAIT_S
        plugin = None
        while len(photos) < len(products) and time.monotonic() < deadline:
            time.sleep(0.25)
            systems = [s for s in sdk.get_systems() if s.has_camera()]
            if plugin is None and systems:
                plugin = Camera(systems[0])
            if plugin is None or not plugin.camera_list().cameras:
                continue
            try:
                photos = plugin.list_photos(100, PhotosRange.ALL)
            except CameraError:  # until MAVSDK has the capture status
                continue
    finally:
        camera.stop()
        sdk.destroy()
    assert sorted(p.index for p in photos) == list(range(5))
    assert {p.file_url for p in photos} == {p.url for p in products}
    assert all(p.position.latitude_deg == 47.0 for p in photos)
