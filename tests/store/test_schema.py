"""The store schema: what the encoders write to a real zarr store decodes back the same.

Each codec pair of :mod:`sarmoco.store.schema` is run through a store on disk
(encode → :class:`Recorder` → files → :class:`RunStore` → decode), and every
table the recorder creates is checked against its declaration.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sarmoco.drivers.samples import (
    AttitudeSample,
    EchoPacket,
    EchoPackets,
    Validity,
    VelocitySample,
)
from sarmoco.errors import RecorderError
from sarmoco.processing.autofocus.report import SubapertureReport
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.store import schema
from sarmoco.store.flags import PulseFlag, PushResult
from sarmoco.store.reader import StoreNav, StorePulses, open_store
from sarmoco.store.recorder import Recorder

T0 = 1_400_000_000_000_000_000
"""A GPS time, ns."""


def nav_rows() -> list[schema.NavRow]:
    """Velocity samples with and without position, attitudes, accepted and rejected, out of
    time order (as a link delivers them)."""
    rows: list[schema.NavRow] = []
    for k in range(12):
        t = T0 + (k if k % 5 else k + 20) * 5_000_000
        result = PushResult.DUPLICATE if k == 7 else PushResult.ACCEPTED
        if k % 3 == 0:
            q = (math.cos(0.1 * k), math.sin(0.1 * k), 0.25 * k, -0.5)
            sample: schema.NavSample = AttitudeSample(t, q, Validity.ATTITUDE, "test", t)
        else:
            pos = None if k % 3 == 1 else (1.5 * k, -2.0 * k, -100.0 - k)
            vel = (30.0 + 0.1 * k, -0.2 * k, 0.01 * k)
            sample = VelocitySample(t, vel, Validity.VELOCITY, "test", t, pos)
        rows.append((sample, None if k == 4 else 1000 + k, result))
    return rows


def same_sample(got: schema.NavSample, want: schema.NavSample) -> None:
    assert type(got) is type(want) and got.t_gps_ns == want.t_gps_ns
    if isinstance(want, VelocitySample):
        assert isinstance(got, VelocitySample)
        assert got.vel_ned == want.vel_ned and got.pos_ned == want.pos_ned
    else:
        assert isinstance(got, AttitudeSample) and got.quat == want.quat


def subaperture(j: int) -> SubapertureReport:
    return SubapertureReport(
        index=j,
        t_center_s=0.5 * j,
        envelope_lines=None,
        phase_lines=None,
        accel_yz_mps2=(0.01 * j, -0.02 * j),
        accel_residual_hz_per_s=0.1 + j,
        kappa=np.array([0.25 * j, 1e-3 * j, -1e-6 * j]),
        kappa_residual_hz_per_s=0.05 * j,
    )


@pytest.fixture
def recorder(tmp_path: Path) -> Recorder:
    return Recorder(tmp_path / "run.zarr", 8, "int16", fsync_interval_s=3600.0)


def test_nav_samples_round_trip_through_a_store(recorder: Recorder) -> None:
    rows = nav_rows()
    recorder.append_nav(**schema.encode_nav(rows))
    recorder.close()
    store = open_store(recorder.path)
    cols = store.read("nav")
    decoded = schema.decode_nav(cols)
    assert len(decoded) == len(rows)
    for got, (want, _, _) in zip(decoded, rows, strict=True):
        same_sample(got, want)
    np.testing.assert_array_equal(cols["rx_ns"], [-1 if rx is None else rx for _, rx, _ in rows])
    np.testing.assert_array_equal(cols["result"], [int(res) for _, _, res in rows])
    # what a replay is offered: the accepted samples, in time order
    accepted = sorted(
        (s for s, _, res in rows if res == PushResult.ACCEPTED), key=lambda s: s.t_gps_ns
    )
    with StoreNav(store, chunk=5) as source:
        replayed = []
        while not source.eof:
            replayed += source.poll()
    assert len(replayed) == len(accepted) == len(rows) - 1
    for sample, want in zip(replayed, accepted, strict=True):
        assert isinstance(sample, VelocitySample | AttitudeSample)
        same_sample(sample, want)


def test_a_nav_kind_the_decoder_does_not_know_is_an_error() -> None:
    cols = schema.encode_nav(nav_rows()[:2])
    cols["kind"][1] = 2
    with pytest.raises(RecorderError, match="nav/kind"):
        schema.decode_nav(cols)


def test_pulse_flags_round_trip_to_the_packets_they_came_from(recorder: Recorder) -> None:
    packets = [
        EchoPacket(3, T0 + k * 1_000_000, 0, 8, k % 2 == 0, k % 3 == 0, k % 5 == 0, k % 4 == 1)
        for k in range(10)
    ]
    flags = PulseFlag.of_packets(EchoPackets.of(packets, 8))
    flags[2] |= PulseFlag.NAV_GAP
    echo = np.arange(10 * 8 * 2, dtype=np.int16).reshape(10, 8, 2)
    recorder.append_pulses([p.t_gps_ns for p in packets], range(10), [3] * 10, flags, echo)
    recorder.close()
    rows = np.zeros((4, 8, 2), np.int16)
    got: list[EchoPacket] = []
    with StorePulses(open_store(recorder.path)) as source:
        while not source.eof:
            batch = source.read_into(rows)
            np.testing.assert_array_equal(
                rows[: len(batch)], echo[len(got) : len(got) + len(batch)]
            )
            got += batch
    assert got == packets
    with pytest.raises(RecorderError, match="do not fit"):
        StorePulses(open_store(recorder.path)).read_into(np.zeros((4, 8), np.complex64))


def test_autofocus_rows_hold_the_report_fields(recorder: Recorder) -> None:
    subs = [subaperture(j) for j in range(4)]
    recorder.append_rows(schema.AUTOFOCUS, schema.encode_autofocus(subs[:1]))
    recorder.append_rows(schema.AUTOFOCUS, schema.encode_autofocus(subs[1:]))
    recorder.close()
    cols = open_store(recorder.path).read("autofocus")
    assert set(cols) == set(schema.AUTOFOCUS.columns)
    np.testing.assert_array_equal(cols["t_center_s"], [s.t_center_s for s in subs])
    np.testing.assert_array_equal(cols["a_y_mps2"], [s.accel_yz_mps2[0] for s in subs])
    np.testing.assert_array_equal(cols["a_z_mps2"], [s.accel_yz_mps2[1] for s in subs])
    np.testing.assert_array_equal(cols["kappa"], np.stack([s.kappa for s in subs]))
    np.testing.assert_array_equal(
        cols["accel_residual_hz_per_s"], [s.accel_residual_hz_per_s for s in subs]
    )
    np.testing.assert_array_equal(
        cols["kappa_residual_hz_per_s"], [s.kappa_residual_hz_per_s for s in subs]
    )


def test_every_table_on_disk_is_as_declared(recorder: Recorder) -> None:
    recorder.append_rows(schema.AUTOFOCUS, schema.encode_autofocus([subaperture(1)]))
    track = ReferenceTrack.from_velocity(np.zeros(3), np.array([30.0, 1.0, 0.0]), T0, "right")
    recorder.set_attribute(schema.REFERENCE_TRACK_ATTR, schema.encode_reference_track(track))
    recorder.close()
    store = open_store(recorder.path)
    declared = [
        schema.pulses_table(8, "int16", raw_echoes=True),
        schema.NAV,
        schema.INS_RAW,
        schema.INS_BYTES,
        schema.MOTION,
        schema.AUTOFOCUS,
    ]
    assert store.tables() == sorted(spec.name for spec in declared)
    for spec in declared:
        ds = store.dataset(spec.name)
        assert set(ds.variables) == set(spec.columns), spec.name
        for name, col in spec.columns.items():
            assert ds[name].dtype == col.dtype, (spec.name, name)
            assert ds[name].dims == (spec.row_dim, *col.dims), (spec.name, name)
            assert ds[name].shape[1:] == col.shape, (spec.name, name)
    attrs = store.attrs
    assert attrs[schema.LAYOUT_ATTR] == schema.STORE_LAYOUT_VERSION
    assert attrs[schema.COMPLETE_ATTR] is True
    ref = attrs[schema.REFERENCE_TRACK_ATTR]
    assert ref["t0_ns"] == T0 and ref["v0_mps"] == pytest.approx(math.hypot(30.0, 1.0))
    np.testing.assert_allclose(ref["x_hat_ned"], track.x_hat)
