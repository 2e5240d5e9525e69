"""The MAVLink camera component's answer times to a pymavlink ground station on 127.0.0.1.

Run as a script: ``python bench/bench_camera.py [--commands 200]``. Prints the time from
the component's start to the first HEARTBEAT the ground station receives, and the
median, 95th percentile and largest round trip of MAV_CMD_REQUEST_MESSAGE →
CAMERA_INFORMATION and MAV_CMD_VIDEO_START_CAPTURE → COMMAND_ACK, ms.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import time
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.daemon.camera import CameraComponent
from sarmoco.daemon.config import CameraConfig
from sarmoco.daemon.status import Counters


def round_trips(gcs: Any, cmd: int, param1: float, reply: str, n: int) -> list[float]:
    """Seconds from sending ``cmd`` until ``reply`` arrives, ``n`` times, sorted."""
    out = []
    for _ in range(n):
        t = time.perf_counter()
        gcs.mav.command_long_send(1, mav.MAV_COMP_ID_CAMERA, cmd, 0, param1, 0, 0, 0, 0, 0, 0)
        if gcs.recv_match(type=reply, blocking=True, timeout=2.0) is None:
            raise SystemExit(f"no {reply} within 2 s")
        out.append(time.perf_counter() - t)
    return sorted(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--commands", type=int, default=200, help="round trips per command")
    n = parser.parse_args().commands
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    gcs = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
        dialect="ardupilotmega",
    )  # fmt: skip
    cfg = CameraConfig(enabled=True, link=f"udpout:127.0.0.1:{port}", capture_at_start=False)
    t0 = time.monotonic()
    camera = CameraComponent(
        cfg, "SAR", dict, lambda: None, lambda _on, _item: None, Counters()
    ).start()
    try:
        gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0)
        print(f"first HEARTBEAT after {1e3 * (time.monotonic() - t0):.1f} ms")
        for name, cmd, param1, reply in (
            ("REQUEST_MESSAGE -> CAMERA_INFORMATION", mav.MAV_CMD_REQUEST_MESSAGE,
             mav.MAVLINK_MSG_ID_CAMERA_INFORMATION, "CAMERA_INFORMATION"),
            ("VIDEO_START_CAPTURE -> COMMAND_ACK", mav.MAV_CMD_VIDEO_START_CAPTURE, 0,
             "COMMAND_ACK"),
        ):  # fmt: skip
            rt = round_trips(gcs, cmd, param1, reply, n)
            print(
                f"{name}: median {1e3 * statistics.median(rt):.2f} ms, 95th percentile "
                f"{1e3 * rt[int(0.95 * (n - 1))]:.2f} ms, max {1e3 * rt[-1]:.2f} ms ({n} commands)"
            )
    finally:
        camera.stop()
        gcs.close()


if __name__ == "__main__":
    main()
