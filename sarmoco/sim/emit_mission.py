"""The simulated autopilot's survey mission, as it drives a MAVLink camera over UDP.

An autopilot flying a survey mission with camera items forwards them to a MAVLink
camera component (ArduPilot's MAVLink camera backend, ``CAM1_TYPE = 6``; PX4 re-emits
them as commands): at the start of each leg MAV_CMD_VIDEO_START_CAPTURE, at its end
MAV_CMD_VIDEO_STOP_CAPTURE. The mission this emitter flies has, for leg ``k``, a
waypoint at the leg's start (item ``4k + 1``), a VIDEO_START_CAPTURE item (``4k + 2``), a
waypoint at the leg's end (``4k + 3``) and a VIDEO_STOP_CAPTURE item (``4k + 4``); item 0
is home. As ArduPilot does, MISSION_CURRENT names the navigation item being flown: the
leg's end waypoint while the leg is flown (:func:`leg_item`).

What it sends (system 1, component 1, to the camera component's ``udpin:`` port): a
HEARTBEAT at 1 Hz (also while it waits for the camera, which answers the address it
hears from), and at each leg's start MISSION_CURRENT then COMMAND_LONG
VIDEO_START_CAPTURE, at its end MISSION_CURRENT then COMMAND_LONG VIDEO_STOP_CAPTURE,
addressed to :data:`CAMERA_SYSTEM_ID`, :data:`CAMERA_COMPONENT_ID`. It counts the
COMMAND_ACKs it hears by result.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from functools import partial
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sarmoco.drivers.clock import NS_PER_S
from sarmoco.sim.emit_mavlink import COMPONENT_ID, HEARTBEAT_PERIOD_S, SYSTEM_ID, AutopilotSpeaker
from sarmoco.sim.pacing import Event
from sarmoco.sim.transports import Link

CAMERA_SYSTEM_ID = SYSTEM_ID
"""System id of the camera component addressed (the vehicle's)."""

CAMERA_COMPONENT_ID = mavlink2.MAV_COMP_ID_CAMERA
"""Component id of the camera component addressed (100, ArduPilot's CAM1)."""


def leg_item(leg: int) -> int:
    """MISSION_CURRENT ``seq`` while leg ``leg`` (0-based) is flown: its end waypoint."""
    return 4 * leg + 3


class MissionEmitter(AutopilotSpeaker):
    """Plays a survey mission's capture commands to a MAVLink camera component.

    Parameters
    ----------
    link : Link
        UDP to the camera component's ``udpin:`` port.
    legs : sequence of (int, int)
        Start and end of each straight leg, scenario GPS ns.
    rank : int
        Tie-break of this emitter's events against others due at the same time.
    """

    protocol = "mavlink2-mission"

    def __init__(self, link: Link, legs: Sequence[tuple[int, int]], rank: int = 9) -> None:
        super().__init__(link, None, 0, rank)
        self.legs = [(int(a), int(b)) for a, b in legs]
        self.camera_heard = False
        self.acks: dict[str, int] = {}
        """COMMAND_ACKs heard from the camera, by ``<command>:<result>`` names."""

    def events(self) -> Iterator[Event]:
        """A heartbeat each second from the first leg's start to the last leg's end, and
        the capture commands at each leg's ends."""
        if not self.legs:
            return
        period = round(HEARTBEAT_PERIOD_S * NS_PER_S)
        beats = [
            Event(t, self.rank, partial(self._heartbeat, t))
            for t in range(self.legs[0][0], self.legs[-1][1] + period, period)
        ]
        commands = [
            Event(t, self.rank, partial(self._capture, t, k, start))
            for k, (t0, t1) in enumerate(self.legs)
            for t, start in ((t0, True), (t1, False))
        ]
        yield from sorted(beats + commands, key=lambda e: e.t_ns)

    def _capture(self, t_ns: int, leg: int, start: bool) -> None:
        """MISSION_CURRENT and the capture command at one end of leg ``leg``."""
        self.now_ns = t_ns
        seq = leg_item(leg) if start else leg_item(leg) + 2  # past the stop: the next leg's
        self._tx.mission_current_send(seq)
        self._count("MISSION_CURRENT")
        cmd = mavlink2.MAV_CMD_VIDEO_START_CAPTURE if start else mavlink2.MAV_CMD_VIDEO_STOP_CAPTURE
        self._tx.command_long_send(
            CAMERA_SYSTEM_ID, CAMERA_COMPONENT_ID, cmd, 0, 0, 0, 0, 0, 0, 0, 0
        )
        self._count("VIDEO_START_CAPTURE" if start else "VIDEO_STOP_CAPTURE")

    def on_message(self, msg: Any, now_ns: int | None) -> None:
        if msg.get_srcComponent() != CAMERA_COMPONENT_ID:
            return
        if msg.get_type() == "HEARTBEAT":
            self.camera_heard = True
        elif msg.get_type() == "COMMAND_ACK":
            name = f"{_name(mavlink2.enums['MAV_CMD'], msg.command)}:" + _name(
                mavlink2.enums["MAV_RESULT"], msg.result
            )
            self.acks[name] = self.acks.get(name, 0) + 1

    def ready(self) -> bool:
        return self.camera_heard

    def connect_hint(self) -> dict[str, Any]:
        where = self.link.describe()
        return {"connect": f"udpin:{where.get('to')}", "system_id": SYSTEM_ID,
                "component_id": COMPONENT_ID}  # fmt: skip

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "messages": dict(self.sent), "acks": dict(self.acks)}


def _name(enum: dict[int, Any], value: int) -> str:
    """The name of an enum value (its number when unknown)."""
    entry = enum.get(value)
    return str(value) if entry is None else str(entry.name)
