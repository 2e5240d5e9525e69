"""slcan adapter status: the Lawicel ``Fxx`` answer, the bus state it reports, and the
simulated adapter's ``can-errors`` / ``can-bus-off`` switches."""

from __future__ import annotations

import pytest

from sarmoco.drivers.slcan_status import BusState, bus_state, parse_status
from sarmoco.errors import ConfigError
from sarmoco.sim.faults import PacketFaultInjector, parse_faults


@pytest.mark.parametrize(
    ("line", "flags"),
    [("F00\r", 0), ("F24\r", 0x24), ("FA4\r", 0xA4), ("Fa4\r", 0xA4), ("F\r", None),
     ("FZZ\r", None), ("F1234\r", None), ("t1230\r", None), ("\r", None)],
)  # fmt: skip
def test_parse_status(line: str, flags: int | None) -> None:
    assert parse_status(line) == flags


@pytest.mark.parametrize(
    ("flags", "state"),
    [(0x00, BusState.OK), (0x01 | 0x02 | 0x08 | 0x40, BusState.OK), (0x04, BusState.WARNING),
     (0x80, BusState.WARNING), (0x24, BusState.PASSIVE), (0x20, BusState.PASSIVE),
     (0xA4, BusState.BUS_OFF), (0xA0, BusState.BUS_OFF)],
)  # fmt: skip
def test_bus_state_of_the_flags(flags: int, state: BusState) -> None:
    assert bus_state(flags) is state


def test_can_switches_drop_frames_only_while_bus_off() -> None:
    """``can-bus-off=0.1:0.05``: frames every 1 ms lose exactly those 100-150 ms after the
    first; ``can-errors`` (error passive) loses none."""
    f = parse_faults(["can-errors=0.02:0.05", "can-bus-off=0.1:0.05"])
    assert (f.ins.can_errors_at_s, f.ins.can_errors_s) == (0.02, 0.05)
    assert (f.ins.bus_off_at_s, f.ins.bus_off_s) == (0.1, 0.05) and not f.radar.any
    inj = PacketFaultInjector(f.ins, seed=0)
    out: list[bytes] = []
    for k in range(200):
        inj.send(k.to_bytes(2, "big"), out.append, 10**18 + k * 1_000_000)
    lost = sorted(set(range(200)) - {int.from_bytes(p, "big") for p in out})
    assert lost == list(range(100, 150)) and inj.counts.bus_off_lost == 50
    assert inj.since_first_s(10**18 + 120_000_000) == pytest.approx(0.12)


@pytest.mark.parametrize(
    ("spec", "match"), [("can-bus-off=1", "A:B"), ("can-errors=1:0", "duration")]
)
def test_can_switch_errors_name_the_switch(spec: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_faults([spec])
