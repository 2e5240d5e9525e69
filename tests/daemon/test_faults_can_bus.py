"""CAN adapter error states through the real processes: ``sarmoco sim --serve`` (SBG CAN
through a simulated slcan adapter on a pty, VITA over UDP) into ``sarmoco run``,
ku-vehicle x0.1, ``/status`` polled every 50 ms while the daemon runs.

The adapter reports its bus error passive (Lawicel status flags 0x24, frames still pass)
for 0.4 s from 0.5 s after its first frame, then bus-off (0xA4, every frame lost) for
0.3 s from 1.3 s. The daemon asks for the flags (``F``) ten times a second
(:class:`~sarmoco.drivers.slcan_status.SlcanStatusBus`): it counts the two steps into a
worse state (``ins_bus_error_states``), logs each change once (into each state and back),
reports the INS unhealthy in ``/status`` while the bus is passive or off and healthy again
after, bridges the 0.3 s silence (``NAV_BRIDGED``, within ``ins.bridge_gap_s``), and
focuses the targets.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from typing import Any

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.daemon.flags import NAV_UNUSABLE, PulseFlag
from sarmoco.daemon.store import open_store
from tests.daemon.test_faults_ins_link import SCALE, _free_tcp_port
from tests.daemon.test_faults_wire import SINC_PSLR_DB

FAULTS = ("can-errors=0.5:0.4", "can-bus-off=1.3:0.3")


def _status(port: int) -> dict[str, Any] | None:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
            s.sendall(b"GET /status HTTP/1.0\r\nHost: x\r\n\r\n")
            body = b"".join(iter(lambda: s.recv(65536), b"")).split(b"\r\n\r\n", 1)
        doc: dict[str, Any] = json.loads(body[1])
        return doc
    except (OSError, ValueError, IndexError):
        return None


@pytest.mark.xfail(
    strict=False,
    reason="open: failed once in a quiet fresh-clone CI run (CI9) with the store complete, "
    "53 pulses bridged and PSLR -12.93..-13.08 dB, so on one of its /status or log timing "
    "checks (a 0.4 s passive window polled from outside); passes alone",
)
def test_slcan_error_passive_and_bus_off(
    tmp_path_factory: pytest.TempPathFactory, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path_factory.mktemp("can_bus_off")
    port = _free_tcp_port()
    seen: list[dict[str, Any]] = []
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            doc = _status(port)
            if doc is not None:
                seen.append(doc)
            time.sleep(0.05)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        summary = run_loopback(out, SCALE, ins="sbg-can", faults=FAULTS, status={"http_port": port})
    finally:
        done.set()
        watcher.join()
    logs = capfd.readouterr().err
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    truth = json.loads((out / "truth.json").read_text())
    stats = truth["wire"]["links"]["ins1"]["stats"]
    ins = [d["components"]["ins"] for d in seen if "ins" in d["components"]]
    faulted = [c["detail"] for c in ins if "CAN bus" in c["detail"]]
    counts = seen[-1]["counters"]
    pulses = store.read("pulses", ["t_ns", "flags"])
    t_s = (pulses["t_ns"] - truth["wire"]["shift_ns"] - truth["t0_ns"]) / 1e9
    unusable = (pulses["flags"] & np.uint32(NAV_UNUSABLE)) != 0
    bridged = (pulses["flags"] & np.uint32(PulseFlag.NAV_BRIDGED)) != 0
    pslr = [p["pslr_az_db"] for p in summary["image"]["points"][:3]]
    print(f"slcan error passive 0.4 s + bus-off 0.3 s: adapter {stats['status_answers']} status "
          f"answers, {stats['error_answers']} with error flags, {stats['faults']['bus_off_lost']} "
          f"frames lost bus-off; ins_bus_error_states {counts.get('ins_bus_error_states')}; "
          f"{len(faulted)} of {len(ins)} /status reads unhealthy ({sorted(set(faulted))}); "
          f"last: {ins[-1]}; {unusable.sum()} pulses flagged, {bridged.sum()} bridged "
          f"({t_s[bridged].min() if bridged.any() else None} .. "
          f"{t_s[bridged].max() if bridged.any() else None} s); "
          f"azimuth PSLR {pslr} dB")  # fmt: skip
    assert stats["faults"]["bus_off_lost"] > 50  # 0.3 s of frames at 100 Hz x 3
    assert stats["error_answers"] >= 5
    assert counts["ins_bus_error_states"] == 2  # ok -> passive -> bus-off, then back to ok
    assert logs.count("CAN bus passive (adapter status flags 0x24)") == 1, logs
    assert logs.count("CAN bus bus-off (adapter status flags 0xA4)") == 1, logs
    assert logs.count("CAN bus ok (adapter status flags 0x00) again") == 2, logs
    assert any("bus-off" in d for d in faulted) and any("passive" in d for d in faulted)
    assert all(not c["ok"] for c in ins if "CAN bus" in c["detail"])
    assert ins[-1]["ok"] or "CAN bus" not in ins[-1]["detail"]  # recovered
    assert not unusable.any()  # the 0.3 s silence is bridged, nothing lost
    assert bridged.any() and not bridged[t_s < 0.5].any()
    assert all(p <= SINC_PSLR_DB + 1.0 for p in pslr), pslr
