"""The simulated autopilot's survey mission (:mod:`sarmoco.sim.emit_mission`), played on a
virtual clock into a file and read back with pymavlink."""

from __future__ import annotations

from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from sarmoco.sim.emit_mission import CAMERA_COMPONENT_ID, MissionEmitter, leg_item
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.survey import SurveyPattern, leg_times_ns, survey_scenario, survey_spec
from sarmoco.sim.transports import FileLink


def test_each_leg_starts_and_stops_the_capture_at_its_ends(tmp_path: Path) -> None:
    """Two legs of a survey: MISSION_CURRENT (the leg's end waypoint) then
    VIDEO_START_CAPTURE at each leg's start, MISSION_CURRENT (the next leg's start
    waypoint) then VIDEO_STOP_CAPTURE at its end, to the camera component, in that order
    among heartbeats; the legs are the survey pattern's."""
    spec = survey_spec(2, 2.0)
    scn = survey_scenario(load_preset("ku-vehicle", 0.1), spec, per_leg=1, margin_s=0.5)
    legs = leg_times_ns(scn, spec)
    pattern = SurveyPattern.of(scn, spec)
    assert legs[1][0] - legs[0][1] == round(pattern.turn_s * 1e9)
    path = tmp_path / "mission.raw"
    emitter = MissionEmitter(FileLink(path), legs)
    events = list(emitter.events())
    for event in events:
        event.action()
    emitter.close()
    assert [e.t_ns for e in events] == sorted(e.t_ns for e in events)
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega", notimestamps=True)
    seen = []
    while (msg := conn.recv_match(type=["MISSION_CURRENT", "COMMAND_LONG"])) is not None:
        if msg.get_type() == "MISSION_CURRENT":
            seen.append(msg.seq)
        else:
            assert (msg.target_system, msg.target_component) == (1, CAMERA_COMPONENT_ID)
            seen.append(msg.command)
    start, stop = mav.MAV_CMD_VIDEO_START_CAPTURE, mav.MAV_CMD_VIDEO_STOP_CAPTURE
    assert seen == [leg_item(0), start, leg_item(1) - 2, stop, leg_item(1), start, 9, stop]
    assert emitter.sent["HEARTBEAT"] >= 2 + pattern.turn_s
