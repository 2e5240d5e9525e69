"""``sarmoco sim``: simulated hardware, as files or as live links on loopback.

Files::

    sarmoco sim --preset ku-vehicle --scale 0.1 --out DIR

Live links (the simulator waits for the daemon on every link, then plays)::

    sarmoco sim --preset ku-vehicle --scale 0.1 --serve \\
        --radar udp://127.0.0.1:40000 --ins mavlink:udpout:127.0.0.1:14550

``--radar``: ``udp://127.0.0.1:PORT`` (datagrams sent to the daemon's port) or
``tcp://127.0.0.1:PORT`` (we listen; port 0 picks one). ``--ins`` (repeatable):
``mavlink:udpout:127.0.0.1:PORT`` (sent to the daemon's ``udpin:`` port),
``mavlink:tcp:127.0.0.1:PORT`` (we listen), ``mavlink:pty``, ``sbg:pty``,
``sbg-can:slcan-pty`` (a simulated slcan adapter), ``sbg-can:socketcand:PORT``
(a socketcand server on 127.0.0.1). ``--mission udpout:127.0.0.1:PORT`` (with
``--motion survey:LEGS:LEG_S``): the autopilot's survey mission, sent to the daemon's
MAVLink camera component (``camera.link = "udpin:127.0.0.1:PORT"``): a video start
capture at the start of each leg and a stop at its end (:mod:`sarmoco.sim.emit_mission`).
With ``--out`` the INS recordings are chosen by protocol name (``--ins mavlink --ins
sbg``; default all three).

With ``--serve`` one JSON line goes to stdout as soon as every link is open::

    {"event": "listening", "pid": ..., "radar": {...}, "ins": [{...}], ...}

each link with ``connect`` (what the daemon opens: a URL, a pty path, or the
python-can bus arguments); at the end a second line ``{"event": "done", ...}``.
With ``--out`` a single line ``{"event": "written", "dir": ..., "files": [...]}``.

Pacing: ``--realtime`` (default with ``--serve``) plays at wall-clock speed and puts
the run *now* on the host clock (every GPS time on the wire is shifted by
``truth.json`` ``wire.shift_ns``), so MAVLink TIMESYNC relates the autopilot's boot
clock to the daemon host's clock as on real hardware; ``--speed F`` plays F times
faster and ``--fast`` on a virtual clock (both leave times as simulated: TIMESYNC
answers then carry simulated time, and a daemon should map MAVLink time with
SYSTEM_TIME). The bytes sent are the same in every mode; only their timing differs.

Faults (``--fault``, repeatable): ``loss=P``, ``corrupt=P``, ``dup=P``, ``reorder=P``
(each optionally ``@radar`` or ``@ins``), ``ins-dropout=START_S:DURATION_S``,
``clock-offset=S``, ``clock-drift=PPM``, ``clock-step=AT_S:STEP_S``
(:mod:`sarmoco.sim.faults`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from sarmoco.app.simarray import (
    add_array_arguments,
    check_array_arguments,
    run_array,
    serve_array,
)
from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT
from sarmoco.errors import ConfigError
from sarmoco.sim.array_scenario import ARRAY_PRESET
from sarmoco.sim.echostream import streams
from sarmoco.sim.emit_mission import MissionEmitter
from sarmoco.sim.emit_radar import RadarEmitter
from sarmoco.sim.emitter import Emitter, WireTime
from sarmoco.sim.extended import SCENES, load_scene
from sarmoco.sim.faults import Faults, parse_faults
from sarmoco.sim.ins import GRADES
from sarmoco.sim.insemitters import InsEmitterOptions, host_port, live_ins_emitter
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.outfiles import NAV_FILES, TRUTH_FILE, TruthWriter, write_run
from sarmoco.sim.player import Pacing, play_emitters
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import DEFAULT_LEVER_ARM_M, PRESETS, radar_table
from sarmoco.sim.survey import leg_times_ns, survey_scenario, survey_spec
from sarmoco.sim.transports import Link, TcpServerLink, UdpOutLink


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the arguments of ``sarmoco sim`` to its parser (with this module's text as help)."""
    p.description = __doc__
    p.add_argument(
        "--preset", required=True, choices=(*PRESETS, ARRAY_PRESET), help="scenario preset"
    )
    p.add_argument("--scale", type=float, default=1.0, help="scenario scale in (0, 1] (default 1)")
    p.add_argument(
        "--scene", default="points", choices=SCENES,
        help="points: the preset's targets; extended: terrain-shaded clutter and corner "
        "reflectors (sarmoco.sim.extended; default points)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="seed of noise, INS errors and faults")
    p.add_argument("--pulses", type=int, default=None, help="pulses to simulate (default: all)")
    p.add_argument(
        "--motion",
        default="ideal",
        metavar="KIND[:LOG]",
        help="ideal | turbulence | flightlog:PATH.tlog | survey:LEGS:LEG_S[:TURN_DEG_S] "
        "(straight legs of LEG_S s joined by banked 180-degree turns at TURN_DEG_S deg/s, "
        "by default the real log's 11.6; one target in the middle half of each leg; "
        "default ideal)",
    )
    p.add_argument("--motion-seed", type=int, default=0, help="seed of the turbulence")
    p.add_argument("--ins-grade", default="tactical", choices=sorted(GRADES))
    p.add_argument("--ins-rate", type=float, default=200.0, help="INS output rate, Hz")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, metavar="DIR", help="write files into DIR")
    where.add_argument("--serve", action="store_true", help="serve live links on loopback")
    p.add_argument("--radar", metavar="URL", help="udp://127.0.0.1:PORT | tcp://127.0.0.1:PORT")
    p.add_argument("--ins", action="append", metavar="SPEC", help="INS link (repeatable)")
    p.add_argument(
        "--mission", metavar="udpout:HOST:PORT",
        help="live, with --motion survey: the survey mission's capture commands to the "
        "daemon's MAVLink camera component",
    )  # fmt: skip
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_true", help="real time (default with --serve)")
    pace.add_argument("--fast", action="store_true", help="as fast as possible (default --out)")
    pace.add_argument("--speed", type=float, help="real time sped up by this factor")
    p.add_argument(
        "--fault", action="append", metavar="SPEC", help="fault to inject (repeatable; see above)"
    )
    p.add_argument("--payload", default="int16", choices=("int16", "float32"))
    p.add_argument("--stream-id", type=int, default=0, help="VITA 49 stream ID")
    p.add_argument("--wait", type=float, default=60.0, help="wait this long for the daemon, s")
    p.add_argument(
        "--lead", type=float, default=1.0, help="live: time before the first INS sample, s"
    )
    p.add_argument(
        "--linger", type=float, default=1.0, help="live: keep answering after the end, s"
    )
    p.add_argument("--truth", type=Path, help="live: also write the truth record here")
    p.add_argument(
        "--pregenerate", type=Path, metavar="FILE",
        help="live: render every pulse's wire samples into FILE (.npy, memory-mapped; 16 kB "
        "per 4096-sample int16 pulse) before listening, so that playback only sends: a "
        "full-rate radar's echoes cost more to synthesize than to send",
    )  # fmt: skip
    p.add_argument("--leap-s", type=int, default=GPS_LEAP_SECONDS_DEFAULT, help="GPS - UTC, s")
    add_platform_arguments(p)
    add_array_arguments(p)


def add_platform_arguments(p: argparse.ArgumentParser) -> None:
    """The platform's arguments: track heading, look side, crab, lever arm, approach."""
    p.add_argument(
        "--heading-deg", type=float, default=0.0, help="track heading, deg from north (default 0)"
    )
    p.add_argument("--look-side", default="right", choices=("right", "left"))
    p.add_argument(
        "--lever-arm",
        type=_lever_arm,
        default=None,
        metavar="F,R,D",
        help="INS to antenna phase centre, body frame, m (default: the preset's "
        f"{','.join(map(str, DEFAULT_LEVER_ARM_M))})",
    )
    p.add_argument(
        "--crab-deg", type=float, default=0.0, metavar="DEG",
        help="body yaw minus track heading, deg, positive clockwise from above (a crosswind w "
        "across an airspeed V crabs by asin(w / V), nose into the wind); the INS reports it "
        "and the antenna, fixed to the body, squints with it (default 0)",
    )  # fmt: skip
    p.add_argument(
        "--approach-s", type=float, default=0.0, metavar="S",
        help="fly S s of straight track before the targets' aperture (default 0)",
    )  # fmt: skip


def _lever_arm(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        f, r, d = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not three numbers F,R,D in m") from None
    return f, r, d


def platform_arguments(argv: Sequence[str]) -> argparse.Namespace:
    """Parse only the platform arguments (see :func:`add_platform_arguments`)."""
    p = argparse.ArgumentParser(prog="sarmoco sim", add_help=False)
    add_platform_arguments(p)
    return p.parse_args(list(argv))


def scenario_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The :func:`load_preset` overrides of the platform arguments (heading, look side, crab,
    arm, approach)."""
    over: dict[str, Any] = {
        "heading_rad": math.radians(args.heading_deg),
        "look_side": args.look_side,
        "crab_rad": math.radians(args.crab_deg),
    }
    if args.lever_arm is not None:
        over["lever_arm_m"] = args.lever_arm
    if args.approach_s:
        over["approach_s"] = args.approach_s
    return over


def _motion(text: str, seed: int) -> MotionSpec:
    kind, _, path = text.partition(":")
    if kind == "flightlog" and path:
        return MotionSpec("flightlog", seed=seed, log_path=Path(path))
    if kind in ("ideal", "turbulence") and not path:
        return MotionSpec("ideal" if kind == "ideal" else "turbulence", seed=seed)
    legs, _, rest = path.partition(":")
    leg_s, _, turn = rest.partition(":")
    if kind == "survey" and legs.isdigit() and _number(leg_s) and (not turn or _number(turn)):
        return survey_spec(int(legs), float(leg_s), seed, float(turn) if turn else None)
    raise ConfigError(
        f"--motion {text!r}: want ideal, turbulence, flightlog:PATH.tlog or "
        "survey:LEGS:LEG_S[:TURN_DEG_S]"
    )


def _number(text: str) -> bool:
    """Whether ``text`` is a finite positive number."""
    try:
        return math.isfinite(float(text)) and float(text) > 0
    except ValueError:
        return False


def radar_link(url: str) -> Link:
    """The radar link of ``--radar URL``."""
    scheme, sep, rest = url.partition("://")
    if sep and scheme == "udp":
        return UdpOutLink(*host_port(rest, "--radar"))
    if sep and scheme == "tcp":
        return TcpServerLink(*host_port(rest, "--radar"))
    raise ConfigError(f"--radar {url!r}: want udp://127.0.0.1:PORT or tcp://127.0.0.1:PORT")


def build_run(args: argparse.Namespace, faults: Faults) -> SimRun:
    """Simulate the scenario the arguments describe (a long run's echo is streamed:
    :mod:`sarmoco.sim.echostream`)."""
    scn = load_scene(args.scene, args.preset, scale=args.scale, **scenario_overrides(args))
    motion = _motion(args.motion, args.motion_seed)
    if motion.kind == "survey":
        scn = survey_scenario(scn, motion, per_leg=1, margin_s=motion.leg_s / 4)
    return simulate(
        scn,
        motion,
        args.ins_grade,
        ins_rate_hz=args.ins_rate,
        seed=args.seed,
        n_pulses=args.pulses,
        ins_clock_offset_s=faults.clock_offset_s,
        ins_clock_drift_ppm=faults.clock_drift_ppm,
        stream_echo=streams(scn, scn.n_pulses if args.pulses is None else args.pulses),
    )


def _print_line(record: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(record) + "\n")
    sys.stdout.flush()


def _pacing(args: argparse.Namespace, live: bool) -> Pacing:
    realtime = args.realtime or args.speed is not None or (live and not args.fast)
    speed = args.speed or 1.0
    return Pacing(
        realtime=realtime,
        speed=speed,
        pin_to_host=live and realtime and speed == 1.0,
        lead_s=args.lead if live else 0.5,
        leap_s=args.leap_s,
    )


def _write_files(args: argparse.Namespace, run: SimRun, faults: Faults) -> int:
    nav = args.ins or list(NAV_FILES)
    truth = write_run(
        run, faults, args.out, nav=nav, payload=args.payload, stream_id=args.stream_id,
        seed=args.seed, pacing=_pacing(args, live=False),
    )  # fmt: skip
    files = [d.get("path") for d in truth["wire"]["links"].values()]
    _print_line(
        {"event": "written", "dir": str(args.out), "files": [*files, str(args.out / TRUTH_FILE)]}
    )
    return 0


def _serve(args: argparse.Namespace, run: SimRun, faults: Faults) -> int:
    if not args.radar and not args.ins:
        raise ConfigError("sim --serve: give --radar and/or --ins")
    feed = InsFeed.from_run(run, faults)
    truth = None if args.truth is None else TruthWriter(args.truth, run)
    emitters: dict[str, Emitter] = {}
    try:
        if args.radar:
            radar = RadarEmitter(
                radar_link(args.radar), run.scenario.radar, run.t_ns, run.echo,
                payload=args.payload, stream_id=args.stream_id, faults=faults.radar,
                seed=args.seed * 16, rank=0,
            )  # fmt: skip
            emitters["radar"] = radar
            if args.pregenerate is not None:
                radar.pregenerate(args.pregenerate)
        for k, spec in enumerate(args.ins or [], start=1):
            options = InsEmitterOptions(
                faults.ins, args.seed * 16 + k, k, faults.mavlink_rogue_system
            )
            emitters[f"ins{k}"] = live_ins_emitter(spec, feed, options)
        if args.mission:
            emitters["mission"] = _mission_emitter(args.mission, run)
        _print_line(
            {
                "event": "listening",
                "pid": os.getpid(),
                "preset": args.preset,
                "scale": args.scale,
                "n_pulses": int(run.t_ns.size),
                "radar": emitters["radar"].describe() if "radar" in emitters else None,
                "ins": [e.describe() for name, e in emitters.items() if name.startswith("ins")],
                "mission": emitters["mission"].describe() if "mission" in emitters else None,
                "radar_params": radar_table(run.scenario.radar),
                "truth": None if args.truth is None else str(args.truth),
            }
        )

        def on_start(wire: WireTime) -> None:
            if truth is not None:
                truth.write(feed, faults, emitters, wire)

        result = play_emitters(
            list(emitters.values()), _pacing(args, live=True), wait_s=args.wait,
            linger_s=args.linger, on_start=on_start,
        )  # fmt: skip
        if truth is not None:
            truth.write(feed, faults, emitters, result.wire)
        _print_line(
            {
                "event": "done",
                "events": result.events,
                "wall_s": round(result.wall_s, 3),
                "waited_s": round(result.waited_s, 3),
                "shift_ns": result.wire.shift_ns,
                "links": {name: e.stats() for name, e in emitters.items()},
            }
        )
    finally:
        for e in emitters.values():
            e.close()
    return 0


def _mission_emitter(where: str, run: SimRun) -> MissionEmitter:
    """The survey mission's emitter on ``--mission udpout:HOST:PORT``.

    Raises
    ------
    ConfigError
        If ``where`` is not that form, or the motion is not a survey.
    """
    kind, _, address = where.partition(":")
    if kind != "udpout":
        raise ConfigError(f"--mission {where!r}: want udpout:127.0.0.1:PORT")
    if run.motion.kind != "survey":
        raise ConfigError("--mission: needs --motion survey:LEGS:LEG_S (the legs it captures)")
    link = UdpOutLink(*host_port(address, "--mission"))
    return MissionEmitter(link, leg_times_ns(run.scenario, run.motion))


def _stop(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(0)


def run_command(args: argparse.Namespace) -> int:
    """Handler of ``sarmoco sim``; returns the exit status."""
    if args.serve and args.out is not None:
        raise ConfigError("sim: --out and --serve exclude each other")
    check_array_arguments(args)
    if args.preset == ARRAY_PRESET and args.out is not None:
        return run_array(args)
    if args.preset == ARRAY_PRESET:
        signal.signal(signal.SIGTERM, _stop)
        return serve_array(args, radar_link(args.radar), _pacing(args, live=True))
    faults = parse_faults(args.fault)
    run = build_run(args, faults)
    if args.out is not None:
        return _write_files(args, run, faults)
    signal.signal(signal.SIGTERM, _stop)
    return _serve(args, run, faults)
