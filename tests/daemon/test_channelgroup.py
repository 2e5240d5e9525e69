"""Grouping an array radar's per-channel packets into pulses."""

from __future__ import annotations

import numpy as np

from sarmoco.daemon.channelgroup import MAX_OPEN_PULSES, ChannelGrouper, GroupedPulse
from sarmoco.drivers.samples import EchoPacket, EchoPackets
from sarmoco.store.flags import PulseFlag


def _packet(channel: int, t_ns: int, loss: bool = False) -> EchoPacket:
    return EchoPacket(channel, t_ns, 0, 4, True, loss, False, 0)


def _rows(packets: list[EchoPacket]) -> np.ndarray:
    """Each packet's samples: 1000 t + channel (so a row says where it belongs)."""
    return np.array([[p.t_gps_ns * 1000 + p.stream_id] * 4 for p in packets], np.complex64)


def _add(g: ChannelGrouper, packets: list[EchoPacket]) -> list[GroupedPulse]:
    """Hand ``packets`` to ``g`` as a radar source returns them (one batch)."""
    return g.add(_rows(packets), EchoPackets.of(packets, 4))


def test_pulses_come_out_whole_with_channels_in_place() -> None:
    g = ChannelGrouper(range(3), (4,), np.complex64)
    packets = [_packet(c, t) for t in (1, 2) for c in (2, 0, 1)]  # channels out of order
    packets[4] = _packet(0, 2, loss=True)
    out = _add(g, packets[:4]) + _add(g, packets[4:])
    assert [p.t_ns for p in out] == [1, 2]
    for p in out:
        np.testing.assert_array_equal(p.samples[:, 0].real, p.t_ns * 1000 + np.arange(3))
    assert out[0].flags == 0 and out[1].flags == int(PulseFlag.SAMPLE_LOSS)
    assert (g.incomplete, g.foreign, g.duplicates) == (0, 0, 0)


def test_missing_foreign_and_repeated_packets_are_counted() -> None:
    g = ChannelGrouper(range(2), (4,), np.complex64)
    packets = [_packet(0, 1), _packet(0, 1), _packet(5, 1)]  # repeat, stream 5 of no channel
    packets += [_packet(0, t) for t in range(2, 2 + MAX_OPEN_PULSES)]  # pulse 1 never completes
    assert _add(g, packets) == []
    assert (g.incomplete, g.foreign, g.duplicates) == (1, 1, 1) and g.foreign_ids == {5}
    assert g.flush() == MAX_OPEN_PULSES
    assert g.incomplete == MAX_OPEN_PULSES + 1


def test_channels_are_placed_by_the_configured_stream_ids() -> None:
    """A digitiser numbers its streams as it likes: channel ``c`` is the pair whose stream
    ID is ``stream_ids[c]``, whatever the numbers (channel 0's ID 2 is channel 2's
    place under the default numbering); the default numbering's IDs are then foreign."""
    ids = [2, 0x8000_0001, 0xFFFF_FFFF]
    g = ChannelGrouper(ids, (4,), np.complex64)
    packets = [_packet(sid, 1) for sid in reversed(ids)] + [_packet(1, 1)]
    out = _add(g, packets)
    assert len(out) == 1 and (g.foreign, g.foreign_ids) == (1, {1})
    np.testing.assert_array_equal(
        out[0].samples[:, 0].real, np.array([1000 + sid for sid in ids], np.float32)
    )
