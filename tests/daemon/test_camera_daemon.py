"""``sarmoco run`` with its MAVLink camera component, driven by a pymavlink ground station.

The daemon runs with ``camera.capture_at_start`` off on UDP radar and MAVLink links; the
test sends the simulator's pulses in three thirds and starts capture (VIDEO_START_CAPTURE)
before the second and stops it (VIDEO_STOP_CAPTURE) after: the store holds exactly the
pulses of the second third, and its ``captures`` attribute the one interval. Then INS
frames arrive and stop: the ground station hears the "no INS data" fault cleared, then
the INS dropout announced at MAV_SEVERITY_CRITICAL. A run of the simulator's files
announces every tile it stores with CAMERA_IMAGE_CAPTURED, once, with its time and the
INS's position.
"""

from __future__ import annotations

import datetime
import json
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.app.demo import read_json_line
from sarmoco.app.simconfig import loopback_config
from sarmoco.daemon.camera import UNKNOWN_DEG_E7
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.survey import leg_times_ns, survey_scenario, survey_spec
from sarmoco.store.reader import open_store
from tests.daemon.test_daemon_process import (
    N_PULSES,
    PY,
    Daemon,
    SimFiles,
    daemon_config,
    free_port,
    http_get,
    mavlink_frames,
    sim,  # noqa: F401 - the module's fixture
    wait_finished,
    wait_focused,
    wait_status,
)

WAIT_S = 10.0
"""Longest wait for one message of the component, s."""


def ground_station(port: int) -> Any:
    """A pymavlink ground station (system 255, component 190) listening on 127.0.0.1:``port``."""
    return mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
        dialect="ardupilotmega",
    )  # fmt: skip


def live_camera_config(
    sim: SimFiles,  # noqa: F811 - the imported fixture's type
    path: Path,
    radar_port: int,
    ins_port: int,
    http_port: int,
    gcs_port: int,
    store_per_capture: bool = False,
) -> Path:
    """A daemon configuration on live UDP links with the camera component on
    ``gcs_port``, idle until a start capture, faults announced at most once a minute."""
    return daemon_config(
        sim, path,
        radar={"link": f"udp://127.0.0.1:{radar_port}"},
        ins={"link": f"udpin:127.0.0.1:{ins_port}"},
        status={"http_port": http_port},
        camera={"enabled": True, "link": f"udpout:127.0.0.1:{gcs_port}",
                "capture_at_start": False, "store_per_capture": store_per_capture,
                "statustext_interval_s": 60.0},
    )  # fmt: skip


def recv(gcs: Any, kind: str, text: str = "") -> Any:
    """The next ``kind`` message from the camera component (a STATUSTEXT starting ``text``)."""
    deadline = time.monotonic() + WAIT_S
    while (left := deadline - time.monotonic()) > 0:
        msg = gcs.recv_match(type=kind, blocking=True, timeout=left)
        if msg is not None and msg.get_srcComponent() == mav.MAV_COMP_ID_CAMERA:
            if kind != "STATUSTEXT" or msg.text.startswith(text):
                return msg
    raise AssertionError(f"no {kind} {text!r} from the camera within {WAIT_S} s")


def command(gcs: Any, cmd: int) -> int:
    """Send a command to the camera component; return the result of its COMMAND_ACK."""
    gcs.mav.command_long_send(1, mav.MAV_COMP_ID_CAMERA, cmd, 0, 0, 0, 0, 0, 0, 0, 0)
    deadline = time.monotonic() + WAIT_S
    while (left := deadline - time.monotonic()) > 0:
        ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=left)
        if ack is not None and ack.command == cmd:
            return int(ack.result)
    raise AssertionError(f"command {cmd} not acknowledged")


def wait_accounted(port: int) -> dict[str, float]:
    """Poll /status until every pulse is recorded or let go (not captured); the counters."""
    deadline = time.monotonic() + WAIT_S
    while True:
        counters: dict[str, float] = json.loads(http_get(port, "/status")[1])["counters"]
        done = counters["pulses_not_captured"] + counters["pipeline_pulses_received"]
        if done == N_PULSES:
            return counters
        assert time.monotonic() < deadline, counters
        time.sleep(0.1)


def send(tx: socket.socket, packets: list[bytes], port: int) -> None:
    for k, packet in enumerate(packets):
        tx.sendto(packet, ("127.0.0.1", port))
        if k % 50 == 49:
            time.sleep(0.01)  # bursts well within the socket buffer


def test_ground_station_captures_a_strip_and_hears_an_ins_dropout(
    sim: SimFiles,  # noqa: F811 - the imported fixture
    tmp_path: Path,
) -> None:
    radar_port, ins_port, gcs_port = (free_port(socket.SOCK_DGRAM) for _ in range(3))
    http_port = free_port(socket.SOCK_STREAM)
    gcs = ground_station(gcs_port)
    config = live_camera_config(
        sim, tmp_path / "camera.toml", radar_port, ins_port, http_port, gcs_port
    )
    d = Daemon(config, tmp_path / "camera.zarr")
    thirds = [sim.packets[:300], sim.packets[300:700], sim.packets[700:]]
    try:
        d.started()
        assert recv(gcs, "HEARTBEAT").type == mav.MAV_TYPE_CAMERA
        assert recv(gcs, "STATUSTEXT", "SAR: no INS data").severity == mav.MAV_SEVERITY_CRITICAL
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            send(tx, thirds[0], radar_port)
            before = wait_status(http_port, "counters", "radar_frames", 300)["counters"]
            assert command(gcs, mav.MAV_CMD_VIDEO_START_CAPTURE) == mav.MAV_RESULT_ACCEPTED
            send(tx, thirds[1], radar_port)
            wait_status(http_port, "counters", "radar_frames", 700)  # read: in the ring
            assert command(gcs, mav.MAV_CMD_VIDEO_STOP_CAPTURE) == mav.MAV_RESULT_ACCEPTED
            send(tx, thirds[2], radar_port)
            wait_status(http_port, "counters", "radar_frames", len(sim.packets))
            after = wait_accounted(http_port)
            for frame in mavlink_frames(sim.dir / "nav.tlog", 200):
                tx.sendto(frame, ("127.0.0.1", ins_port))
                time.sleep(0.002)
        cleared = recv(gcs, "STATUSTEXT", "cleared: SAR: no INS data")
        assert cleared.severity == mav.MAV_SEVERITY_INFO
        dropout = recv(gcs, "STATUSTEXT", "SAR: INS stale")
        assert dropout.severity == mav.MAV_SEVERITY_CRITICAL
        assert d.stop() == 0
    finally:
        d.kill_if_running()
        gcs.close()
    skipped, kept = int(before["pulses_not_captured"]), int(after["pipeline_pulses_received"])
    assert skipped > 250 and kept > 350  # the pulses of the first and second third
    store = open_store(d.store)
    assert store.committed("pulses") == kept
    np.testing.assert_array_equal(store.read("pulses")["t_ns"], sim.t_ns[skipped : skipped + kept])
    (interval,) = store.attrs["captures"]["intervals"]
    start, stop = (datetime.datetime.fromisoformat(interval[k]) for k in ("start_utc", "stop_utc"))
    assert start < stop


def test_every_stored_tile_is_announced_once_with_its_time_and_position(
    sim: SimFiles,  # noqa: F811 - the imported fixture
    tmp_path: Path,
) -> None:
    """The simulator's ``.vrt`` and ``.tlog`` as file links, capturing from the start: the
    ground station hears one CAMERA_IMAGE_CAPTURED per tile of the store (those closed at
    the stop included), with the store's index, the UTC middle of the tile's pulses and
    the position unknown (the simulator's tactical INS gives velocity and attitude only;
    the position of a fix is checked with a real pymavlink ground station in
    ``tests/daemon/test_camera.py``)."""
    gcs_port, http_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    gcs = ground_station(gcs_port)
    config = daemon_config(
        sim, tmp_path / "files.toml", status={"http_port": http_port},
        camera={"enabled": True, "link": f"udpout:127.0.0.1:{gcs_port}"},
    )  # fmt: skip
    d = Daemon(config, tmp_path / "files.zarr")
    announced: list[Any] = []
    try:
        d.started()
        wait_finished(http_port)
        wait_focused(http_port)
        assert d.stop() == 0, d.log.read_text()
        while (msg := gcs.recv_match(type="CAMERA_IMAGE_CAPTURED", blocking=True,
                                     timeout=1.0)) is not None:  # fmt: skip
            announced.append(msg)
    finally:
        d.kill_if_running()
        gcs.close()
    store = open_store(d.store)
    assert store.n_images >= 2
    assert [m.image_index for m in announced] == list(range(store.n_images))
    assert not np.isfinite(store.read("nav", ["lla"])["lla"]).any()  # tactical: no fix
    leap = int(sim.table["ins"].get("gps_minus_utc_s", 18))
    for msg in announced:
        _, attrs = store.image(msg.image_index)
        mid = (int(attrs["t0_ns"]) + int(attrs["t1_ns"])) // 2
        assert msg.time_utc == gps_ns_to_unix_ns(mid, leap) // 1000
        assert msg.lat == msg.lon == UNKNOWN_DEG_E7
        assert msg.file_url.endswith(f"/images/tile_{msg.image_index:06d}")


def test_each_capture_is_a_strip_store_closed_complete_and_announced(
    sim: SimFiles,  # noqa: F811 - the imported fixture
    tmp_path: Path,
) -> None:
    """``camera.store_per_capture``: two captures give two stores, each closed complete at
    its stop (every pulse of the capture, its ``captures`` and ``strip`` attributes, the
    run's metrics) while the daemon runs on, the second named by the mission item the
    ground station reported current (MISSION_CURRENT) before it, and each announced with
    CAMERA_IMAGE_CAPTURED (its store's URL) and a STATUSTEXT at MAV_SEVERITY_INFO."""
    radar_port, gcs_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    http_port = free_port(socket.SOCK_STREAM)
    gcs = ground_station(gcs_port)
    config = live_camera_config(
        sim,
        tmp_path / "strips.toml",
        radar_port,
        free_port(socket.SOCK_DGRAM),
        http_port,
        gcs_port,
        store_per_capture=True,
    )
    d = Daemon(config, tmp_path / "leg.zarr")
    strips: list[Any] = []
    try:
        assert d.started()["store"] == f"{tmp_path / 'leg'}-*.zarr"
        recv(gcs, "HEARTBEAT")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for number, (first, last) in enumerate([(0, 300), (600, 1000)], start=1):
                if number == 2:
                    gcs.mav.mission_current_send(7)
                    send(tx, sim.packets[300:600], radar_port)  # between strips: let go
                    wait_status(http_port, "counters", "radar_frames", 600)
                assert command(gcs, mav.MAV_CMD_VIDEO_START_CAPTURE) == mav.MAV_RESULT_ACCEPTED
                send(tx, sim.packets[first:last], radar_port)
                wait_status(http_port, "counters", "radar_frames", last)
                assert command(gcs, mav.MAV_CMD_VIDEO_STOP_CAPTURE) == mav.MAV_RESULT_ACCEPTED
                stored = recv(gcs, "STATUSTEXT", f"SAR: strip {number}")
                assert stored.severity == mav.MAV_SEVERITY_INFO
                while (msg := recv(gcs, "CAMERA_IMAGE_CAPTURED")).image_index != number - 1:
                    pass  # the newest one again, after a capture status
                strips.append(msg)
                assert d.proc.poll() is None  # the daemon runs on
        assert d.stop() == 0
    finally:
        d.kill_if_running()
        gcs.close()
    paths = sorted(tmp_path.glob("leg-*.zarr"))
    assert len(paths) == 2 and paths[1].name.endswith("-item7.zarr") and "item" not in paths[0].name
    assert [m.file_url for m in strips] == [p.resolve().as_uri() for p in paths]
    for number, (path, msg) in enumerate(zip(paths, strips, strict=True), start=1):
        store = open_store(path)
        assert store.attrs["complete"]
        n = store.committed("pulses")
        assert n == store.attrs["metrics"]["pulses_received"] > 250
        t_ns = store.read("pulses")["t_ns"]
        start = int(np.searchsorted(sim.t_ns, t_ns[0]))
        np.testing.assert_array_equal(t_ns, sim.t_ns[start : start + n])
        assert store.attrs["strip"] == {
            "number": number,
            "mission_item": 7 if number == 2 else None,
        }
        (interval,) = store.attrs["captures"]["intervals"]
        assert interval["stop_utc"] is not None
        leap = int(sim.table["ins"].get("gps_minus_utc_s", 18))
        assert msg.time_utc == gps_ns_to_unix_ns((int(t_ns[0]) + int(t_ns[-1])) // 2, leap) // 1000
        assert msg.lat == msg.lon == UNKNOWN_DEG_E7  # no INS: no absolute position
    assert open_store(paths[0]).read("pulses")["t_ns"][-1] < sim.t_ns[300]  # first third only


def test_a_survey_mission_captures_one_strip_per_leg(tmp_path: Path) -> None:
    """``sarmoco sim --serve --motion survey:2:2:36 --mission``: the simulated autopilot
    flies two 2 s legs joined by a banked turn (36 deg/s: 5 s) and sends VIDEO_START_CAPTURE and
    VIDEO_STOP_CAPTURE (after MISSION_CURRENT) at each leg's ends to the daemon's camera
    component: the daemon stores one strip per leg, named by the leg's mission item, each
    holding the pulses of its leg only (none of the turn), and announces each at the INS's
    absolute position in the middle of its leg."""
    radar_url = f"udp://127.0.0.1:{free_port(socket.SOCK_DGRAM)}"
    ins_port, camera_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    sim_proc = subprocess.Popen(
        [*PY, "sim", "--preset", "ku-vehicle", "--scale", "0.1", "--motion", "survey:2:2:36",
         "--ins-grade", "ideal", "--serve", "--radar", radar_url,
         "--ins", f"mavlink:udpout:127.0.0.1:{ins_port}",
         "--mission", f"udpout:127.0.0.1:{camera_port}", "--truth", str(tmp_path / "truth.json")],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    daemon: Daemon | None = None
    try:
        hello = read_json_line(sim_proc, "the simulator", 60.0)
        config = loopback_config(
            tmp_path, load_preset("ku-vehicle", 0.1), hello["radar"]["connect"],
            ("mavlink", hello["ins"][0]["connect"]), 0,
            {"camera": {"enabled": True, "link": f"udpin:127.0.0.1:{camera_port}",
                        "capture_at_start": False, "store_per_capture": True}},
        )  # fmt: skip
        daemon = Daemon(config, tmp_path / "leg.zarr")
        daemon.started()
        assert sim_proc.wait(timeout=60) == 0
        done = read_json_line(sim_proc, "the simulator", 5.0)
        assert daemon.stop() == 0, daemon.log.read_text()
    finally:
        if daemon is not None:
            daemon.kill_if_running()
        sim_proc.kill()
        sim_proc.wait()
        assert sim_proc.stdout is not None
        sim_proc.stdout.close()
    paths = sorted(tmp_path.glob("leg-*.zarr"))
    assert [p.name[-11:] for p in paths] == ["-item3.zarr", "-item7.zarr"]
    truth = json.loads((tmp_path / "truth.json").read_text())
    t_wire = np.asarray(truth["pulses"]["t_ns"], np.int64) + truth["wire"]["shift_ns"]
    motion = survey_spec(2, 2.0, turn_rate_dps=36.0)
    scn = survey_scenario(load_preset("ku-vehicle", 0.1), motion, per_leg=1, margin_s=0.5)
    legs = leg_times_ns(scn, motion)
    prf = scn.radar.prf_hz
    for path, (t0, t1) in zip(paths, legs, strict=True):
        store = open_store(path)
        assert store.attrs["complete"]
        t_ns = store.read("pulses")["t_ns"] - truth["wire"]["shift_ns"]
        assert t0 - 0.1e9 <= t_ns[0] and t_ns[-1] <= t1 + 0.1e9  # its leg, no turn
        assert store.committed("pulses") >= 0.9 * 2.0 * prf  # nearly all of it
    assert sum(open_store(p).committed("pulses") for p in paths) < 0.5 * t_wire.size
    acks = done["links"]["mission"]["acks"]
    assert acks == {"MAV_CMD_VIDEO_START_CAPTURE:MAV_RESULT_ACCEPTED": 2,
                    "MAV_CMD_VIDEO_STOP_CAPTURE:MAV_RESULT_ACCEPTED": 2}  # fmt: skip


def test_mavproxy_shows_the_ins_dropout(
    sim: SimFiles,  # noqa: F811 - the imported fixture
    tmp_path: Path,
) -> None:
    """MAVProxy, a real ground station, headless (``--daemon``) on the camera component's
    link: the INS's frames arrive, then stop, and MAVProxy prints the STATUSTEXT of the
    dropout (``AP: SAR: INS stale, ...``) on its console."""
    gcs_port, ins_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    console = tmp_path / "mavproxy.out"
    with console.open("w") as out:
        mavproxy = subprocess.Popen(
            [sys.executable, str(Path(sys.executable).parent / "mavproxy.py"),
             f"--master=udpin:127.0.0.1:{gcs_port}", "--daemon", "--no-state",
             "--default-modules=link", f"--state-basedir={tmp_path}"],
            stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=tmp_path,
        )  # fmt: skip
    config = daemon_config(
        sim, tmp_path / "mavproxy.toml",
        radar={"link": f"udp://127.0.0.1:{free_port(socket.SOCK_DGRAM)}"},
        ins={"link": f"udpin:127.0.0.1:{ins_port}"},
        camera={"enabled": True, "link": f"udpout:127.0.0.1:{gcs_port}",
                "statustext_interval_s": 60.0},
    )  # fmt: skip
    d = Daemon(config, tmp_path / "mavproxy.zarr")
    try:
        d.started()
        wait_console(console, "AP: SAR: no INS data")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for frame in mavlink_frames(sim.dir / "nav.tlog", 200):
                tx.sendto(frame, ("127.0.0.1", ins_port))
                time.sleep(0.002)
        wait_console(console, "AP: cleared: SAR: no INS data")
        wait_console(console, "AP: SAR: INS stale, ")
        assert d.stop() == 0
    finally:
        d.kill_if_running()
        mavproxy.terminate()
        try:
            mavproxy.wait(timeout=10)
        except subprocess.TimeoutExpired:
            mavproxy.kill()
            mavproxy.wait()


def wait_console(console: Path, text: str) -> None:
    """Wait until a line of MAVProxy's console output starts with ``text``."""
    deadline = time.monotonic() + 2 * WAIT_S
    while time.monotonic() < deadline:
        if any(line.startswith(text) for line in console.read_text().splitlines()):
            return
        time.sleep(0.1)
    raise AssertionError(f"MAVProxy showed no {text!r}:\n{console.read_text()}")


def test_a_strip_store_that_cannot_be_created_is_announced_and_the_daemon_runs_on(
    sim: SimFiles,  # noqa: F811 - the imported fixture
    tmp_path: Path,
) -> None:
    """A start capture whose strip's store cannot be created (its folder is a file): the
    ground station hears the recorder's error at MAV_SEVERITY_ERROR, the daemon keeps
    answering and stops cleanly."""
    (tmp_path / "taken").write_text("a file where the strips' folder should be")
    gcs_port, http_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    gcs = ground_station(gcs_port)
    config = live_camera_config(
        sim,
        tmp_path / "taken.toml",
        free_port(socket.SOCK_DGRAM),
        free_port(socket.SOCK_DGRAM),
        http_port,
        gcs_port,
        store_per_capture=True,
    )
    d = Daemon(config, tmp_path / "taken" / "leg.zarr", log=tmp_path / "taken.log")
    try:
        d.started()
        recv(gcs, "HEARTBEAT")
        assert command(gcs, mav.MAV_CMD_VIDEO_START_CAPTURE) == mav.MAV_RESULT_ACCEPTED
        error = recv(gcs, "STATUSTEXT", "SAR: recorder: cannot create")
        assert error.severity == mav.MAV_SEVERITY_ERROR
        assert command(gcs, mav.MAV_CMD_VIDEO_STOP_CAPTURE) == mav.MAV_RESULT_ACCEPTED
        counters = json.loads(http_get(http_port, "/status")[1])["counters"]
        assert counters["processing_errors"] == 1
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
        gcs.close()
