"""CAN adapter error states through the real processes: ``sarmoco sim --serve`` (SBG CAN
through a simulated slcan adapter on a pty, VITA over UDP) into ``sarmoco run``,
ku-vehicle x0.1, ``/status`` polled every 50 ms while the daemon runs.

The adapter reports its bus error passive (Lawicel status flags 0x24, frames still pass)
for 1.5 s from 0.2 s after its first frame (the INS link starts 0.5 s before the first
pulse, so from 0.3 s before the radar to 1.2 s into it), then bus-off (0xA4, every frame
lost) for 0.3 s from 2.0 s (1.5 s into the radar). The daemon asks for the flags (``F``)
ten times a second (:class:`~sarmoco.drivers.slcan_status.SlcanStatusBus`): it counts the
two steps into a worse state (``ins_bus_error_states``), logs each change once, in order
(passive, ok again, bus-off, ok again), the log's times spanning the windows; it reports
the INS unhealthy in ``/status`` while the bus is passive and healthy again after, bridges
the 0.3 s silence (``NAV_BRIDGED``, within ``ins.bridge_gap_s``), and focuses the targets.

The daemon sets its ``/status`` health between processing passes, which take up to about
0.9 s here: a window shorter than that may never show in a ``/status`` read (a 0.4 s
passive window did not, in 3 of 4 runs). So ``/status`` is checked on the 1.5 s passive
window, which opens before the radar (no pass running); the 0.3 s bus-off (it must stay
shorter than ``ins.bridge_gap_s``, 0.4 s, to be bridged) on the counter and the log.
"""

from __future__ import annotations

import json
from datetime import datetime
from itertools import pairwise

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.sim.player import Pacing
from sarmoco.store.flags import NAV_UNUSABLE, PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.statuswatch import watching_status
from tests.daemon.test_faults_ins_link import SCALE, _free_tcp_port
from tests.daemon.test_faults_wire import SINC_PSLR_DB

PASSIVE_S = (0.2, 1.5)
"""Error-passive window: start after the INS link's first frame, and length, s."""
BUS_OFF_S = (2.0, 0.3)
"""Bus-off window: start after the INS link's first frame, and length, s."""
FAULTS = (f"can-errors={PASSIVE_S[0]}:{PASSIVE_S[1]}", f"can-bus-off={BUS_OFF_S[0]}:{BUS_OFF_S[1]}")
LEAD_S = Pacing().lead_s
"""The INS link's first frame leads the first pulse by this, s."""
STATE_LAG_S = 0.3
"""Most a logged state change may trail (or, a status request apart, lead) the adapter's, s."""
PASSIVE = "CAN bus passive (adapter status flags 0x24)"
BUS_OFF = "CAN bus bus-off (adapter status flags 0xA4)"
OK_AGAIN = "CAN bus ok (adapter status flags 0x00) again"


def _bus_log(logs: str) -> list[tuple[str, float]]:
    """The CAN driver's bus state records among the daemon's JSON log lines, in order:
    (the state as logged after the link's name, UNIX time of the record in s)."""
    out: list[tuple[str, float]] = []
    for line in logs.splitlines():
        if line.startswith("{") and '"sarmoco.drivers.can_source"' in line and "CAN bus" in line:
            rec = json.loads(line)
            state = rec["msg"].split(": ", 1)[1]
            out.append((state, datetime.fromisoformat(rec["ts"]).timestamp()))
    return out


def test_slcan_error_passive_and_bus_off(
    tmp_path_factory: pytest.TempPathFactory, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path_factory.mktemp("can_bus_off")
    port = _free_tcp_port()
    with watching_status(port, 0.05) as seen:
        summary = run_loopback(out, SCALE, ins="sbg-can", faults=FAULTS, status={"http_port": port})
    logs = capfd.readouterr().err
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    truth = json.loads((out / "truth.json").read_text())
    stats = truth["wire"]["links"]["ins1"]["stats"]
    ins = [d["components"]["ins"] for d in seen if "ins" in d["components"]]
    faulted = [c["detail"] for c in ins if "CAN bus" in c["detail"]]
    counts = seen[-1]["counters"]
    bus_log = _bus_log(logs)
    spans = [round(b[1] - a[1], 3) for a, b in pairwise(bus_log)]
    pulses = store.read("pulses", ["t_ns", "flags"])
    sent_ns = np.asarray(truth["pulses"]["t_ns"])
    t_s = (pulses["t_ns"] - truth["wire"]["shift_ns"] - sent_ns[0]) / 1e9  # from the first
    prf_hz = (sent_ns.size - 1) / ((sent_ns[-1] - sent_ns[0]) / 1e9)
    unusable = (pulses["flags"] & np.uint32(NAV_UNUSABLE)) != 0
    bridged = (pulses["flags"] & np.uint32(PulseFlag.NAV_BRIDGED)) != 0
    pslr = [p["pslr_az_db"] for p in summary.image.points[:3]]
    print(f"slcan error passive {PASSIVE_S[1]} s + bus-off {BUS_OFF_S[1]} s: adapter "
          f"{stats['status_answers']} status answers, {stats['error_answers']} with error flags, "
          f"{stats['faults']['bus_off_lost']} frames lost bus-off; ins_bus_error_states "
          f"{counts.get('ins_bus_error_states')}; logged {[s for s, _ in bus_log]}, "
          f"{spans} s apart; {len(faulted)} of {len(ins)} /status reads unhealthy "
          f"({sum('passive' in d for d in faulted)} passive, "
          f"{sum('bus-off' in d for d in faulted)} bus-off); last: {ins[-1]}; "
          f"{unusable.sum()} pulses flagged, {bridged.sum()} bridged "
          f"({t_s[bridged].min() if bridged.any() else None} .. "
          f"{t_s[bridged].max() if bridged.any() else None} s); "
          f"azimuth PSLR {pslr} dB")  # fmt: skip
    assert stats["faults"]["bus_off_lost"] > 50  # 0.3 s of frames at 100 Hz x 3
    assert stats["error_answers"] >= 0.8 * 10 * (PASSIVE_S[1] + BUS_OFF_S[1])  # asked at 10 Hz
    assert counts["ins_bus_error_states"] == 2  # ok -> passive -> bus-off, then back to ok
    assert [s for s, _ in bus_log] == [PASSIVE, OK_AGAIN, BUS_OFF, OK_AGAIN], bus_log
    passive_gap_s = BUS_OFF_S[0] - sum(PASSIVE_S)
    assert abs(spans[0] - PASSIVE_S[1]) < STATE_LAG_S, spans
    assert abs(spans[1] - passive_gap_s) < STATE_LAG_S, spans
    assert abs(spans[2] - BUS_OFF_S[1]) < STATE_LAG_S, spans
    assert any(PASSIVE in d for d in faulted), sorted(set(faulted))
    assert all(not c["ok"] for c in ins if "CAN bus" in c["detail"])
    assert ins[-1]["ok"] or "CAN bus" not in ins[-1]["detail"]  # recovered
    assert not unusable.any()  # the 0.3 s silence is bridged, nothing lost
    off_s = (BUS_OFF_S[0] - LEAD_S, sum(BUS_OFF_S) - LEAD_S)  # from the first pulse
    assert 0.8 * BUS_OFF_S[1] * prf_hz < bridged.sum() <= BUS_OFF_S[1] * prf_hz + 5
    assert off_s[0] - 0.1 < t_s[bridged].min() and t_s[bridged].max() < off_s[1] + 0.1
    assert all(p <= SINC_PSLR_DB + 1.0 for p in pslr), pslr
