"""Simulated hardware: scenarios, trajectories, INS errors, echoes, wire emitters.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array_run",
    "array_scenario",
    "echostream",
    "emit_mission",
    "emit_radar",
    "emitter",
    "extended",
    "faults",
    "ins",
    "insemitters",
    "insfeed",
    "motionspec",
    "outfiles",
    "pacing",
    "player",
    "run",
    "scenario",
    "survey",
    "transports",
]
