"""``sarmoco run`` in array mode, fed live by the simulator over UDP and MAVLink on 127.0.0.1.

``sarmoco sim --preset mimo-array --scale 0.1 --serve`` plays the scaled MIMO scene (2 Tx x
80 Rx: 160 VITA 49.2 streams, one packet per pair per pulse, and the INS over MAVLink) in
real time to a daemon with the camera component on; the daemon records every channel of
every pulse as it comes and, at its stop, forms the roll-compensated DEM. Its elevation
error against the true terrain meets the array paper's bar and what the replay of the
simulator's files reaches on the same scene, and the replay of the store the daemon wrote
forms the same DEM bit for bit. The ground station hears the DEM announced (STATUSTEXT,
and CAMERA_IMAGE_CAPTURED of the store). With a store per capture, each strip the ground
station starts and stops is closed with the DEM of its own pulses.
"""

from __future__ import annotations

import contextlib
import io
import json
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.app.cli import main
from sarmoco.app.demo import read_json_line
from sarmoco.app.simarray import array_config_table
from sarmoco.app.simconfig import write_config
from sarmoco.sim.array_scenario import load_array_preset
from sarmoco.store.reader import open_store
from tests.app.test_array_mode import _run
from tests.daemon.test_camera_daemon import WAIT_S, command, ground_station, recv, send
from tests.daemon.test_daemon_process import PY, Daemon, free_port, wait_status

SCALE = 0.1


def _report(store: Path, truth: Path) -> dict[str, Any]:
    return dict(json.loads(_run(["report", str(store), "--truth", str(truth), "--json"])))


def _heard(gcs: Any, kinds: set[str]) -> dict[str, Any]:
    """The first message of each of ``kinds`` from the camera component (STATUSTEXT: the
    first starting ``SAR: DEM``)."""
    heard: dict[str, Any] = {}
    deadline = time.monotonic() + WAIT_S
    while heard.keys() != kinds and (left := deadline - time.monotonic()) > 0:
        msg = gcs.recv_match(type=list(kinds - heard.keys()), blocking=True, timeout=left)
        if msg is None or msg.get_srcComponent() != mav.MAV_COMP_ID_CAMERA:
            continue
        if msg.get_type() != "STATUSTEXT" or msg.text.startswith("SAR: DEM"):
            heard[msg.get_type()] = msg
    assert heard.keys() == kinds, f"heard only {sorted(heard)} from the camera in {WAIT_S} s"
    return heard


@pytest.fixture(scope="module")
def array_files(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[], Path]]:
    """The scene written as files by the simulator, once for the module's tests (read only):
    a call waits for the simulator, which runs beside the test that first needs it."""
    sim = tmp_path_factory.mktemp("array-files")
    proc = subprocess.Popen(
        [*PY, "sim", "--preset", "mimo-array", "--scale", str(SCALE), "--out", str(sim)],
        stdout=subprocess.DEVNULL,
    )

    def written() -> Path:
        assert proc.wait(timeout=300) == 0, "sarmoco sim --out failed"
        return sim

    yield written
    proc.kill()
    proc.wait()


def _files_replay(sim: Path, root: Path) -> dict[str, Any]:
    """The scene's files (:func:`array_files`) replayed: its DEM's report."""
    config = _config(sim, root / "files.toml", {})
    _run(["replay", "--config", str(config), "--radar", str(sim / "radar.vrt"),
          "--nav", str(sim / "nav.tlog"), "--out", str(root / "files.zarr")])  # fmt: skip
    return _report(root / "files.zarr", sim / "truth.json")


def _config(out: Path, path: Path, over: dict[str, dict[str, Any]]) -> Path:
    """The simulator's array configuration for the scene, only the roll-compensated DEM
    (the level one is the files' tests'), with ``over``'s keys per section."""
    table = array_config_table(load_array_preset(SCALE), out, "int16")
    table["array"]["record_uncompensated"] = False
    for section, keys in over.items():
        table[section] = table.get(section, {}) | keys
    write_config(path, table)
    return path


def test_live_array_run_records_every_stream_and_forms_the_dem_replay_forms(
    array_files: Callable[[], Path], tmp_path: Path
) -> None:
    radar_url = f"udp://127.0.0.1:{free_port(socket.SOCK_DGRAM)}"
    ins_port, gcs_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    truth = tmp_path / "truth.json"
    sim_proc = subprocess.Popen(
        [*PY, "sim", "--preset", "mimo-array", "--scale", str(SCALE), "--serve",
         "--radar", radar_url, "--ins", f"mavlink:udpout:127.0.0.1:{ins_port}",
         "--truth", str(truth), "--wait", "180"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    gcs = ground_station(gcs_port)
    daemon: Daemon | None = None
    store = tmp_path / "live.zarr"
    try:
        files = _files_replay(array_files(), tmp_path)  # while the live run's echoes are made
        hello = read_json_line(sim_proc, "the simulator", 60.0)
        config = _config(tmp_path, tmp_path / "live.toml", {
            "radar": {"link": hello["radar"]["connect"]},
            "ins": {"link": f"udpin:127.0.0.1:{ins_port}"},
            "camera": {"enabled": True, "link": f"udpout:127.0.0.1:{gcs_port}"},
        })  # fmt: skip
        daemon = Daemon(config, store)
        daemon.started()
        assert sim_proc.wait(timeout=60) == 0
        done = read_json_line(sim_proc, "the simulator", 5.0)
        assert daemon.stop() == 0, daemon.log.read_text()
        heard = _heard(gcs, {"STATUSTEXT", "CAMERA_IMAGE_CAPTURED"})
    finally:
        if daemon is not None:
            daemon.kill_if_running()
        sim_proc.kill()
        sim_proc.wait()
        assert sim_proc.stdout is not None
        sim_proc.stdout.close()
        gcs.close()
    n_pulses = hello["n_pulses"]
    assert done["links"]["radar"]["packets"] == n_pulses * 160
    s = open_store(store)
    metrics = s.attrs["metrics"]
    assert metrics["mode"] == "array" and metrics["pulses"] == metrics["pulses_imaged"] == n_pulses
    p = s.read("pulses", ["t_ns", "channel"])
    assert (p["channel"].reshape(n_pulses, 160) == np.arange(160)).all()
    dem_text, captured = heard["STATUSTEXT"], heard["CAMERA_IMAGE_CAPTURED"]
    assert dem_text.severity == mav.MAV_SEVERITY_INFO
    cells = int(metrics["dem"]["compensated"]["valid_cells"])
    assert dem_text.text == f"SAR: DEM {cells} cells of {n_pulses} pulses"
    assert captured.file_url == store.resolve().as_uri()

    live = _report(store, truth)["dem"]
    print(f"\nlive:  {live}\nfiles: {files['dem']}")
    assert live["std_m"] <= 0.59 and live["within_half_cell"] >= 0.91, live  # the paper's bar
    assert abs(live["mean_m"]) <= 0.1 and live["coverage"] >= 0.8, live
    assert live["std_m"] <= 1.05 * files["dem"]["std_m"], (live, files["dem"])
    assert live["within_half_cell"] >= files["dem"]["within_half_cell"] - 0.01
    assert live["coverage"] >= files["dem"]["coverage"] - 0.01

    again = tmp_path / "again.zarr"
    with contextlib.redirect_stdout(io.StringIO()):
        status = main(["replay", "--config", str(config), "--recording", str(store),
                       "--out", str(again)])  # fmt: skip
    assert status == 0
    want, _ = s.dem("compensated")
    got, _ = open_store(again).dem("compensated")
    np.testing.assert_array_equal(got.height_m, want.height_m)


def _packets(vrt: bytes) -> list[bytes]:
    """The VITA 49 packets of a ``.vrt`` file, in order (the size field counts 32-bit words)."""
    out, pos = [], 0
    while pos < len(vrt):
        size = 4 * (int.from_bytes(vrt[pos : pos + 4], "big") & 0xFFFF)
        out.append(vrt[pos : pos + size])
        pos += size
    return out


def test_each_capture_of_an_array_run_is_a_strip_with_its_dem(
    array_files: Callable[[], Path], tmp_path: Path
) -> None:
    """``camera.store_per_capture`` in array mode: the simulator's packets sent over UDP in
    two halves, each within a start and a stop capture of the ground station, give two
    strip stores, each closed with the DEM of its own pulses and announced."""
    sim = array_files()
    packets = _packets((sim / "radar.vrt").read_bytes())
    radar_port, gcs_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    http_port = free_port(socket.SOCK_STREAM)
    config = _config(sim, tmp_path / "strips.toml", {
        "radar": {"link": f"udp://127.0.0.1:{radar_port}"},
        "status": {"http_port": http_port},
        "camera": {"enabled": True, "link": f"udpout:127.0.0.1:{gcs_port}",
                   "capture_at_start": False, "store_per_capture": True},
    })  # fmt: skip
    gcs = ground_station(gcs_port)
    daemon = Daemon(config, tmp_path / "strip.zarr")
    half = len(packets) // 2 // 160 * 160 + 1  # the context packet, then whole pulses
    # the second strip has more pulses than the first: its count is not the first's
    assert len(packets[half:]) // 160 > (half - 1) // 160
    dems: list[Any] = []
    try:
        daemon.started()
        recv(gcs, "HEARTBEAT")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for part in (packets[:half], packets[half:]):
                assert command(gcs, mav.MAV_CMD_VIDEO_START_CAPTURE) == mav.MAV_RESULT_ACCEPTED
                send(tx, part, radar_port)
                # the strip's pulses stored: a stop lets go of those still being read
                wait_status(http_port, "counters", "pipeline_pulses_received", len(part) // 160)
                assert command(gcs, mav.MAV_CMD_VIDEO_STOP_CAPTURE) == mav.MAV_RESULT_ACCEPTED
                dems.append(recv(gcs, "STATUSTEXT", "SAR: DEM"))
        assert daemon.stop() == 0
    finally:
        daemon.kill_if_running()
        gcs.close()
    paths = sorted(tmp_path.glob("strip-*.zarr"))
    assert len(paths) == 2
    n_pulses = (len(packets) - 1) // 160
    firsts = []
    for path, dem in zip(paths, dems, strict=True):
        store = open_store(path)
        m = store.attrs["metrics"]
        assert m["pulses"] == m["pulses_imaged"] > 10, m
        assert (
            dem.text == f"SAR: DEM {int(m['dem']['compensated']['valid_cells'])} cells of "
            f"{m['pulses']} pulses"
        )
        height, _ = store.dem("compensated")
        assert np.isfinite(height.height_m).any()
        firsts.append(int(store.read("pulses", ["t_ns"])["t_ns"][0]))
    assert sum(open_store(p).attrs["metrics"]["pulses"] for p in paths) == n_pulses
    assert firsts[0] < firsts[1]
