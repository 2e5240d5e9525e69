"""Streaming two-step autofocus against the offline form, and its latency bound."""

from __future__ import annotations

import dataclasses

import numpy as np

from sarmoco.processing.autofocus import (
    AutofocusConfig,
    AutofocusGeometry,
    SlidingSubapertureAutofocus,
    autofocus_offline,
)
from sarmoco.processing.autofocus.splice import line_fit
from sarmoco.processing.imaging.backprojection import backproject
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import point_target_metrics
from tests.processing.autofocus import _synth as S


def _scene() -> S.Synthetic:
    dur = 2.0
    t = np.arange(round(dur * S.PRF_HZ)) / S.PRF_HZ - dur / 2
    d, a = S.sine_motion(t, (0.25, 0.1), (0.3, 0.45))
    xr = [(0, 1000), (4, 920), (-5, 1080), (8, 960), (-10, 1040), (10, 1050)]
    return S.make(dur, [S.ground_target(x, r) for x, r in xr], d, a, snr_db=0.0)


def test_streaming_matches_offline_up_to_a_line() -> None:
    syn = _scene()
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    cfg = AutofocusConfig(phase_passes=1)
    t_ns = np.round(syn.t_s * 1e9).astype(np.int64) + 10**18
    offline, _ = autofocus_offline(syn.rc, t_ns, syn.range_m, geo, cfg)

    af = SlidingSubapertureAutofocus(geo, syn.range_m, cfg)
    los, phase, released_t = [], [], []
    late = 0.0
    for i in range(0, t_ns.size, 37):
        _, corr = af.push(syn.rc[i : i + 37], t_ns[i : i + 37])
        now = float(syn.t_s[min(i + 36, t_ns.size - 1)])
        if corr.t_ns.size:
            late = max(late, now - (float(corr.t_ns[0] - t_ns[0]) * 1e-9 + syn.t_s[0]))
        los.append(corr.los_m)
        phase.append(corr.phase_rad(np.array([1000.0]))[:, 0])
        released_t.append(corr.t_ns)
    _, corr = af.flush()
    los.append(corr.los_m)
    phase.append(corr.phase_rad(np.array([1000.0]))[:, 0])
    released_t.append(corr.t_ns)

    np.testing.assert_array_equal(np.concatenate(released_t), t_ns)
    assert late <= af.latency_s + 37 / S.PRF_HZ + 1e-9
    assert af.latency_s <= cfg.subaperture_s + cfg.hop_s
    t = syn.t_s
    inner = (t > t[0] + 0.3) & (t < t[-1] - 0.3)  # the ends are extrapolated differently
    d_los = np.concatenate(los) - offline.los_m
    d_los -= line_fit(t, d_los[:, None])[:, 0]
    assert np.max(np.abs(d_los[inner])) < 0.01  # m, against 0.46 m of motion
    d_ph = np.concatenate(phase) - offline.phase_rad(np.array([1000.0]))[:, 0]
    d_ph -= line_fit(t[inner], d_ph[inner, None])[:, 0].mean() + 0.0
    d_ph = d_ph[inner] - line_fit(t[inner], d_ph[inner, None])[:, 0]
    assert np.std(d_ph) < 0.5  # rad, against ~150 rad of phase error


def test_offline_recovers_los_and_focus_phase() -> None:
    syn = _scene()
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    t_ns = np.round(syn.t_s * 1e9).astype(np.int64)
    corr, report = autofocus_offline(syn.rc, t_ns, syn.range_m, geo, AutofocusConfig())
    beta = np.arccos(S.DEPTH_M / 1000.0)
    truth = syn.d_yz_m @ np.array([np.sin(beta), np.cos(beta)])
    truth -= line_fit(syn.t_s, truth[:, None])[:, 0]
    assert np.sqrt(np.mean((corr.los_m - truth) ** 2)) < S.RES_M / 4
    ph = corr.phase_rad(np.array([1000.0]))[:, 0]
    err = ph - 4 * np.pi * truth / S.WAVELENGTH_M
    # Between the first and last subaperture centres the rates are interpolated; beyond them
    # (0.2 s at each end) they are extrapolated and the error is larger.
    centres = report.series()["t_center_s"] + syn.t_s[0]
    inner = (syn.t_s >= centres[0]) & (syn.t_s <= centres[-1])
    err = err[inner] - line_fit(syn.t_s[inner], err[inner, None])[:, 0]
    assert np.std(err) < 0.5
    assert len(report.subapertures) == report.series()["kappa"].shape[0] > 10
    assert dataclasses.is_dataclass(report.subapertures[0])


def _stream(
    syn: S.Synthetic, cfg: AutofocusConfig
) -> tuple[np.ndarray, SlidingSubapertureAutofocus]:
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    af = SlidingSubapertureAutofocus(geo, syn.range_m, cfg)
    t_ns = np.round(syn.t_s * 1e9).astype(np.int64) + 10**18
    out = [af.push(syn.rc[i : i + 50], t_ns[i : i + 50])[0] for i in range(0, t_ns.size, 50)]
    out.append(af.flush()[0])
    return np.concatenate(out), af


def _azimuth_pslr(syn: S.Synthetic, rc: np.ndarray) -> list[float]:
    """Azimuth PSLR (dB) of every target, backprojected on the straight reference track."""
    apc = np.column_stack([S.SPEED_MPS * syn.t_s, np.zeros((syn.t_s.size, 2))])
    out = []
    for tg in syn.targets:
        grid = PlaneGrid.centred((tg[0], tg[1], tg[2]), 160, 32, 0.03, 0.06)
        img = backproject(rc, syn.range_m, apc, S.WAVELENGTH_M, grid)
        out.append(point_target_metrics(img, (0.0, 0.0), search_radius_m=1.0).axis0.pslr_db)
    return out


def test_few_targets_in_noise_do_not_lose_focus() -> None:
    """Three targets, the other lines only noise (5 dB under each compressed target per pulse),
    a small residual motion: the default streaming autofocus (16 lines asked for) must use only
    the target lines and leave every target at least as well focused as it came in."""
    dur = 2.0
    t = np.arange(round(dur * S.PRF_HZ)) / S.PRF_HZ - dur / 2
    d, a = S.sine_motion(t, (0.0006, 0.0003), (0.4, 0.7))
    tg = [S.ground_target(0.0, r) for r in (950.0, 1000.0, 1050.0)]
    syn = S.make(dur, tg, d, a, range_span_m=(930.0, 1070.0), snr_db=0.0, seed=3)
    focused, af = _stream(syn, AutofocusConfig())
    before = _azimuth_pslr(syn, syn.rc)
    after = _azimuth_pslr(syn, focused)
    print("azimuth PSLR before", np.round(before, 2), "after", np.round(after, 2))
    assert all(
        s.phase_lines is not None and s.phase_lines.n_used <= 3 for s in af.report.subapertures
    )
    assert np.all(np.array(after) <= np.array(before) + 0.05)
