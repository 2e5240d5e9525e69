"""A live run on links nobody sends to, for tests of the daemon's own threads.

Radar and INS listen on loopback port 0 (any free port), the status endpoint is off; the
tests call :class:`~sarmoco.daemon.runner._LiveRun`'s parts (or nothing) themselves and
end with ``run.shut_down()``.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.runner import _LiveRun
from sarmoco.sim.scenario import load_preset


def idle_run(directory: Path, **recorder: Any) -> _LiveRun:
    """A ku-vehicle x0.05 live run recording to ``directory/run.zarr``; ``recorder`` keys
    (e.g. ``writer_queue``) are added to the configuration's recorder section."""
    cfg = scenario_config(
        load_preset("ku-vehicle", 0.05),
        radar={"link": "udp://127.0.0.1:0"},
        ins={"protocol": "mavlink", "link": "udpin:127.0.0.1:0"},
        recorder={"directory": str(directory), **recorder},
        status={"http_port": 0},
    )
    return _LiveRun(cfg, directory / "run.zarr", threading.Event())
