"""Georeferencing and ``sarmoco export --sicd`` on a simulated scene.

A scene is written by ``sarmoco sim --out`` (ideal INS grade, so that the georeferencing
error is ours alone) and replayed from its SBG log into a store: the store carries the
INS's geodetic positions and the run's geodetic origin; the focused targets land where
the simulator put them on the WGS-84 ellipsoid; the SICD written passes sarkit's
``SicdConsistency`` with no failures and holds our pixels.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import lxml.etree
import numpy as np
import pytest
import sarkit.cphd as sksicd_cphd
import sarkit.crsd as skcrsd
import sarkit.sicd as sksicd
import sarkit.verification as skver
import tifffile

from sarmoco.app.cli import main
from sarmoco.app.export import failures
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_files
from sarmoco.drivers.clock import unix_ns_to_gps_ns
from sarmoco.drivers.mavlink import mavutil, tlog_record
from sarmoco.geodesy import geodetic_to_ned, ned_to_ecef
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    compressed_from_phase_history,
    facing_heading,
)
from sarmoco.processing.types import C_MPS
from sarmoco.products.cphd import read_cphd
from sarmoco.products.georeference import georeference, grid_points, segment_images
from sarmoco.products.geotiff import write_geotiffs
from sarmoco.products.sicd import sicd_product, write_sicd
from sarmoco.sim.insfeed import GEODETIC_ORIGIN
from sarmoco.sim.scenario import load_preset
from sarmoco.store import schema
from sarmoco.store.reader import RunStore, open_store
from sarmoco.store.recorder import Recorder

PIXEL_M = 0.1
"""Grid spacing of the scene's tiles (``imaging.pixel_m``), m."""


@dataclasses.dataclass(frozen=True)
class Scene:
    store: RunStore
    truth: dict
    out: Path


def _replayed_scene(out: Path, look_side: str) -> Scene:
    """The ku-vehicle scene at scale 0.05 (3 point targets), replayed from its SBG log."""
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale", "0.05",
         "--ins-grade", "ideal", "--look-side", look_side, "--out", str(out / "sim")],
        check=True, capture_output=True,
    )  # fmt: skip
    text = (out / "sim" / "sarmoco.toml").read_text()
    text = text.replace('protocol = "mavlink"', 'protocol = "sbg"').replace("nav.tlog", "ins.sbg")
    (out / "sbg.toml").write_text(text)
    cfg = load_config(out / "sbg.toml")
    store = out / "run.zarr"
    replay_files(cfg, out / "sim" / "radar.vrt", out / "sim" / "ins.sbg", store, False)
    truth = json.loads((out / "sim" / "truth.json").read_text())
    return Scene(open_store(store), truth, out)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    """The scene looking right."""
    return _replayed_scene(tmp_path_factory.mktemp("export"), "right")


def _target_errors_m(scene: Scene) -> list[float]:
    """Distance from each target's brightest pixel, through georeference(), to where the
    simulator put it, m."""
    geo = georeference(scene.store)
    cfg = load_config(scene.out / "sbg.toml")
    seg = segment_images(scene.store)[0]
    pts = grid_points(seg.image, seg.track, cfg.geometry.height_m)
    ned = geodetic_to_ned(geo.geodetic(pts), GEODETIC_ORIGIN)
    mag = np.abs(seg.image.data)
    errors = []
    for target in scene.truth["targets"]:
        t = np.asarray(target["pos_ned"])
        near = np.linalg.norm(ned[..., :2] - t[:2], axis=-1) < 2.0
        k = np.unravel_index(np.argmax(np.where(near, mag, 0.0)), mag.shape)
        errors.append(float(np.linalg.norm(ned[k] - t)))
    print(f"georeferencing errors (m): {np.round(errors, 4).tolist()}, fit rms {geo.fit_rms_m}")
    return errors


def test_the_store_keeps_the_sbg_position_and_the_geodetic_origin(scene: Scene) -> None:
    nav = scene.store.read("nav")
    vel = nav["kind"] == schema.NAV_KIND_VELOCITY
    assert vel.sum() > 100
    assert np.isfinite(nav["lla"][vel]).all() and np.isfinite(nav["pos_ned"][vel]).all()
    assert np.isnan(nav["lla"][~vel]).all()
    origin = schema.decode_geodetic_origin(scene.store.attrs, "run")
    first = int(np.argmax(vel & (nav["result"] == 0)))
    assert origin.t_ns == nav["t_ns"][first] and origin.source == "sbg.EKF_NAV"
    # EKF_NAV's altitude above mean sea level plus its undulation: the ellipsoid height
    assert origin.ellipsoid_height
    assert scene.store.attrs["geodetic_origin"]["height"] == schema.HEIGHT_ELLIPSOID
    assert origin.lla == tuple(nav["lla"][first])
    assert np.allclose(nav["pos_ned"][first], 0.0)  # NED about the first fix
    # the origin is where the simulator's INS was at its first sample (scenario NED)
    start = geodetic_to_ned(np.asarray(origin.lla), GEODETIC_ORIGIN)
    apc0 = np.asarray(scene.truth["pulses"]["apc_ned"][0])
    assert np.linalg.norm(start[1:] - (apc0 - scene.truth["scenario"]["lever_arm_m"])[1:]) < 0.01


def test_targets_are_georeferenced_within_a_pixel(scene: Scene) -> None:
    """Each target's brightest pixel, through georeference(), lands within half a pixel
    of the simulator's position for it (ideal INS: the error is the georeferencing's)."""
    errors = _target_errors_m(scene)
    assert len(errors) == 3
    assert max(errors) < PIXEL_M / 2


def test_the_geotiff_puts_the_brightest_target_where_the_simulator_did(scene: Scene) -> None:
    """The GeoTIFF's own tags (read back with tifffile) map its brightest pixel to within
    one pixel of the nearest simulated target, and its top-left pixel (first along-track,
    farthest range: the PNG's orientation) to that image pixel's georeferenced position;
    the affine map fits every pixel to 1 mm."""
    (tif,) = write_geotiffs(scene.store, scene.out)
    assert tif.max_residual_m < 1e-3
    with tifffile.TiffFile(tif.path) as f:
        page = f.pages[0]
        raster, tags = page.asarray(), page.geotiff_tags
    assert tags["GeographicTypeGeoKey"] == 4326 and tags["GTRasterTypeGeoKey"] == 1
    m = np.asarray(tags["ModelTransformation"])
    r, c = np.unravel_index(np.argmax(raster), raster.shape)
    lon, lat = (m[:2, :2] @ [c + 0.5, r + 0.5]) + m[:2, 3]
    # the pixel's height is the ground's (the image plane): compare horizontally
    ned = geodetic_to_ned(np.array([lat, lon, GEODETIC_ORIGIN[2]]), GEODETIC_ORIGIN)
    targets = np.array([t["pos_ned"] for t in scene.truth["targets"]])
    miss = np.min(np.linalg.norm(targets[:, :2] - ned[:2], axis=1))
    print(f"GeoTIFF brightest pixel: {miss:.3f} m from the nearest target")
    assert miss < PIXEL_M
    seg = segment_images(scene.store)[0]
    cfg = load_config(scene.out / "sbg.toml")
    corner = grid_points(seg.image, seg.track, cfg.geometry.height_m)[0, -1]
    lat0, lon0, h0 = georeference(scene.store).geodetic(corner)
    lon, lat = (m[:2, :2] @ [0.5, 0.5]) + m[:2, 3]
    ned = geodetic_to_ned(np.array([lat, lon, h0]), (lat0, lon0, h0))
    assert np.linalg.norm(ned) < 1e-3


def _parabola_peak(values: np.ndarray) -> tuple[float, float]:
    """(row, column) of the largest value of a 2-D array, refined by a parabola through it
    and its neighbours along each axis (fractional indices)."""
    k = np.unravel_index(np.argmax(values), values.shape)
    refined = [float(k[0]), float(k[1])]
    for axis in (0, 1):
        step = np.zeros(2, dtype=int)
        step[axis] = 1
        a, b, c = values[tuple(np.subtract(k, step))], values[k], values[tuple(np.add(k, step))]
        if a - 2 * b + c != 0:
            refined[axis] += 0.5 * (a - c) / (a - 2 * b + c)
    return refined[0], refined[1]


def test_the_geotiff_opens_in_rasterio_with_every_target_at_its_latitude_and_longitude(
    scene: Scene,
) -> None:
    """rasterio (GDAL) reads the GeoTIFF's georeferencing on its own: each simulated
    target's peak in the raster (refined to a fraction of a pixel), mapped through the
    file's geotransform and from the file's CRS to WGS-84, lies within half a pixel of the
    latitude and longitude ``truth.json`` gives it (a geotransform one pixel off misses
    by a pixel)."""
    import rasterio
    import rasterio.warp

    folder = scene.out / "rasterio"
    folder.mkdir()
    (tif,) = write_geotiffs(scene.store, folder)
    with rasterio.open(tif.path) as src:
        raster = src.read(1).astype(np.float64)
        transform, crs = src.transform, src.crs
    assert crs is not None and crs.is_geographic
    misses = []
    for target in scene.truth["targets"]:
        lat, lon, h = target["lla"]
        (x,), (y,) = rasterio.warp.transform("EPSG:4326", crs, [lon], [lat])
        col, row = ~transform @ (x, y)  # where the file says the target is (corner coords)
        r0, c0 = round(row - 0.5) - 10, round(col - 0.5) - 10  # a window of 2 m
        assert r0 >= 1 and c0 >= 1, (row, col)
        r, c = _parabola_peak(raster[r0 : r0 + 21, c0 : c0 + 21])
        x, y = transform @ (c0 + c + 0.5, r0 + r + 0.5)  # the peak pixel's centre
        (lon_at,), (lat_at,) = rasterio.warp.transform(crs, "EPSG:4326", [x], [y])
        misses.append(
            float(np.linalg.norm(geodetic_to_ned(np.array([lat_at, lon_at, h]), (lat, lon, h))[:2]))
        )
    print(f"rasterio: targets' peaks {np.round(misses, 4).tolist()} m from their lat/lon")
    assert len(misses) == 3
    assert max(misses) < PIXEL_M / 2


def test_the_sicd_opens_in_sarpy_with_our_pixels(scene: Scene) -> None:
    """sarpy (``sarpy.io.complex.open``), the reader many SICD users have, reads the file
    ``sarmoco export --sicd`` writes: the same complex pixels, the size and side of track."""
    from sarpy.io.complex import open as open_complex

    out = scene.out / "sarpy.nitf"
    assert main(["export", str(scene.store.path), "--sicd", str(out)]) == 0
    reader = open_complex(str(out))
    (meta,) = reader.get_sicds_as_tuple()
    pixels = reader[:, :]
    seg = segment_images(scene.store)[0]
    assert pixels.dtype == np.complex64
    assert np.array_equal(pixels, seg.image.data.T)  # rows: ground range, columns: along track
    assert (meta.ImageData.NumRows, meta.ImageData.NumCols) == seg.image.data.T.shape
    assert meta.SCPCOA.SideOfTrack == "R"


def test_sicd_export_passes_the_consistency_check_and_holds_our_pixels(
    scene: Scene, capsys: pytest.CaptureFixture[str]
) -> None:
    out = scene.out / "scene.nitf"
    status = main(["export", str(scene.store.path), "--sicd", str(out)])
    assert status == 0, capsys.readouterr().err
    assert failures(skver.SicdConsistency.from_file, out, warnings=True) == []
    with out.open("rb") as f, sksicd.NitfReader(f) as reader:
        pixels = reader.read_image()
        xml = reader.metadata.xmltree
    seg = segment_images(scene.store)[0]
    assert np.array_equal(pixels, seg.image.data.T)  # rows: ground range, columns: along track
    helper = sksicd.XmlHelper(xml)
    assert helper.load("./{*}SCPCOA/{*}SideOfTrack") == "R"
    start = helper.load("./{*}Timeline/{*}CollectStart")
    assert start.year == 2024  # GPS 1.4e18 ns, as UTC
    procs = [p.findtext("{*}Type") for p in xml.findall("./{*}ImageFormation/{*}Processing")]
    assert any("INS motion compensation" in p for p in procs)
    # the frame and origin the geometry went through are stated
    stated = {
        p.get("name"): p.text for p in xml.findall("./{*}ImageFormation/{*}Processing/{*}Parameter")
    }
    origin = schema.decode_geodetic_origin(scene.store.attrs, "run")
    assert stated["geodetic_origin_source"] == origin.source == "sbg.EKF_NAV"
    assert stated["geodetic_origin_height"] == schema.HEIGHT_ELLIPSOID
    lat, lon, _ = (float(v.split()[0]) for v in stated["geodetic_origin"].split(","))
    assert (lat, lon) == pytest.approx(origin.lla[:2], abs=1e-9)
    # the scene centre point is the pixel at SCPPixel, on the ground below the track
    graze = helper.load("./{*}SCPCOA/{*}GrazeAng")
    assert graze == pytest.approx(np.degrees(np.arctan2(100.0, 894.43)), abs=0.1)


def _peak_m(mag: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Position (3,) of the brightest pixel of ``mag`` (pixel positions ``pos``, (n0, n1, 3)),
    refined by a parabola through it and its neighbours along each axis, m."""
    k = np.unravel_index(np.argmax(mag), mag.shape)
    out = pos[k].astype(np.float64)
    for axis in (0, 1):
        step = np.zeros(2, dtype=int)
        step[axis] = 1
        lo, hi = tuple(np.subtract(k, step)), tuple(np.add(k, step))
        a, b, c = mag[lo], mag[k], mag[hi]
        out += 0.5 * (a - c) / (a - 2 * b + c) * (pos[hi] - pos[k])
    return out


def test_cphd_of_the_recorded_echoes_passes_its_check_and_keeps_the_geometry(
    scene: Scene, capsys: pytest.CaptureFixture[str]
) -> None:
    """``export --cphd``: the echoes compensated to the scene centre by the INS pass
    ``CphdConsistency``; read back and backprojected on a 1 cm ground grid about each
    target, every target peaks within 1 cm of where the simulator put it and of where the
    store's own image has it (through its georeference): the export moves no target."""
    out = scene.out / "scene.cphd"
    assert main(["export", str(scene.store.path), "--cphd", str(out)]) == 0, capsys.readouterr()
    assert failures(skver.CphdConsistency.from_file, out, warnings=True) == []
    with out.open("rb") as f, sksicd_cphd.Reader(f) as reader:
        params = reader.metadata.xmltree.findall("./{*}CollectionID/{*}Parameter")
    stated = {p.get("name"): p.text for p in params}
    assert stated["geodetic_origin_source"] == "sbg.EKF_NAV"
    ph = read_cphd(out)
    rc, r_axis, fc = compressed_from_phase_history(ph.signal, ph.freq_hz)
    apc = ph.scene(ph.apc_ecef_m)
    heading = facing_heading(apc, (0, 0, 0))
    geo = georeference(scene.store)
    cfg = load_config(scene.out / "sbg.toml")
    seg = segment_images(scene.store)[0]
    own = ph.scene(geo.ecef(grid_points(seg.image, seg.track, cfg.geometry.height_m)))
    own_mag = np.abs(seg.image.data)
    to_truth, to_own = [], []
    for target in scene.truth["targets"]:
        at = ph.scene(ned_to_ecef(np.asarray(target["pos_ned"]), GEODETIC_ORIGIN))
        grid = PlaneGrid.centred(tuple(at), 41, 41, 0.01, 0.01, heading)
        image = backproject(rc, r_axis, apc, C_MPS / fc, grid, ref_range_m=ph.ref_range_m)
        peak = _peak_m(np.abs(image.data), grid.positions())
        near = np.linalg.norm(own[..., :2] - at[:2], axis=-1) < 1.0
        own_peak = _peak_m(np.where(near, own_mag, 0.0), own)
        to_truth.append(float(np.linalg.norm(peak[:2] - at[:2])))
        to_own.append(float(np.linalg.norm(peak[:2] - own_peak[:2])))
    print(
        f"CPHD refocused targets: {np.round(to_truth, 4).tolist()} m from the simulator's, "
        f"{np.round(to_own, 4).tolist()} m from the store's image"
    )
    assert max(to_truth) < 0.01 and max(to_own) < 0.01


def _crsd_delays_s(
    signal: np.ndarray, ppp: np.ndarray, pvp: np.ndarray, fs: float, expected_s: np.ndarray
) -> np.ndarray:
    """Two-way delay of the echo nearest ``expected_s`` (within 3 ns) in each vector, from
    the file alone: the samples matched-filtered with the chirp its PPPs describe (start
    frequency about ``RefFreq``, rate, length), the peak refined on a 16-times upsampled
    correlation, plus ``RcvStart - TxTime``, s."""
    tau = np.arange(int(np.ceil(ppp["TXmt"][0] * fs))) / fs
    f0 = ppp["FxFreq0"][:, None] - pvp["RefFreq"][:, None]
    replica = np.exp(2j * np.pi * (f0 * tau + 0.5 * ppp["FxRate"][:, None] * tau**2))
    n, up = signal.shape[1] + replica.shape[1], 16
    spec = np.fft.fft(signal, n) * np.conj(np.fft.fft(replica, n))
    padded = np.zeros((spec.shape[0], n * up), dtype=complex)
    padded[:, : n // 2] = spec[:, : n // 2]
    padded[:, -(n - n // 2) :] = spec[:, n // 2 :]
    corr = np.abs(np.fft.ifft(padded, axis=1))
    offset = (pvp["RcvStart"]["Int"] - ppp["TxTime"]["Int"]) + (
        pvp["RcvStart"]["Frac"] - ppp["TxTime"]["Frac"]
    )
    lags = np.arange(n * up) / (up * fs)
    far = np.abs(offset[:, None] + lags[None, :] - expected_s[:, None]) > 3e-9
    k = np.argmax(np.where(far, 0.0, corr), axis=1)
    rows = np.arange(k.size)
    a, b, c = corr[rows, k - 1], corr[rows, k], corr[rows, k + 1]
    return offset + (k + 0.5 * (a - c) / (a - 2 * b + c)) / (up * fs)


def test_the_cphd_of_a_store_imports_and_its_sicd_passes_the_check(
    scene: Scene, capsys: pytest.CaptureFixture[str]
) -> None:
    """``export --cphd`` then ``import-cphd --sicd``: the store's CPHD states no
    polarization (``UNSPECIFIED``), which SICD says as ``UNKNOWN``; on a grid that samples
    the 0.2 m resolution (0.05 m) the spotlight SICD has no failure."""
    cphd, store, sicd = (scene.out / f"roundtrip.{x}" for x in ("cphd", "zarr", "nitf"))
    assert main(["export", str(scene.store.path), "--cphd", str(cphd)]) == 0, capsys.readouterr()
    argv = ["import-cphd", str(cphd), "--out", str(store), "--sicd", str(sicd)]
    assert main([*argv, "--size", "128", "--pixel-m", "0.05"]) == 0, capsys.readouterr()
    assert failures(skver.SicdConsistency.from_file, sicd) == []
    with sicd.open("rb") as f, sksicd.NitfReader(f) as reader:
        helper = sksicd.XmlHelper(reader.metadata.xmltree)
    assert helper.load("./{*}RadarCollection/{*}TxPolarization") == "UNKNOWN"
    assert helper.load("./{*}ImageFormation/{*}TxRcvPolarizationProc") == "UNKNOWN"


def test_crsd_of_the_raw_echoes_passes_its_check_and_keeps_times_positions_and_frequencies(
    scene: Scene, capsys: pytest.CaptureFixture[str]
) -> None:
    """``export --crsd``: the raw echoes with their waveform and geometry pass sarkit's
    ``CrsdConsistency`` (thorough, warnings included). Read back with sarkit: every pulse's
    transmit time is a recorded pulse time of the store (to the nanosecond), its antenna
    position the simulator's within 1 cm, the band and chirp the store's radar; and each
    target's echo, matched-filtered with the chirp the file states and timed by its
    ``RcvStart``, comes back at the two-way range from the file's antenna position to
    where the simulator put the target: no bias beyond the noise, and a scatter at the
    Cramér-Rao bound of the simulator's noise."""
    out = scene.out / "scene.crsd"
    assert main(["export", str(scene.store.path), "--crsd", str(out)]) == 0, capsys.readouterr()
    thorough = functools.partial(skver.CrsdConsistency.from_file, thorough=True)
    assert failures(thorough, out, warnings=True) == []
    with out.open("rb") as f, skcrsd.Reader(f) as reader:
        xml = reader.metadata.xmltree
        ppp = reader.read_ppps("tx")
        signal, pvp = reader.read_channel("rx")
    cfg = load_config(scene.out / "sbg.toml")
    ref = xml.findtext("{*}Global/{*}CollectionRefTime")
    ref_dt = datetime.datetime.fromisoformat(ref.replace("Z", "+00:00"))
    epoch = datetime.datetime(1970, 1, 1, tzinfo=datetime.UTC)
    ref_gps = unix_ns_to_gps_ns((ref_dt - epoch) // datetime.timedelta(microseconds=1) * 1000,
                                cfg.ins.gps_minus_utc_s)  # fmt: skip
    frac_ns = np.round(ppp["TxTime"]["Frac"] * 1e9).astype(np.int64)
    tx_ns = ref_gps + ppp["TxTime"]["Int"] * 1_000_000_000 + frac_ns
    recorded = scene.store.read("pulses", ["t_ns"])["t_ns"]
    assert np.isin(tx_ns, recorded).all()
    truth = scene.truth["pulses"]
    rows = np.searchsorted(np.asarray(truth["t_ns"]), tx_ns)
    true_apc = ned_to_ecef(np.asarray(truth["apc_ned"])[rows], GEODETIC_ORIGIN)
    apc_error = np.linalg.norm(ppp["TxPos"] - true_apc, axis=1)
    radar = cfg.radar
    assert np.all(ppp["FX1"] == radar.carrier_hz - radar.bandwidth_hz / 2)
    assert np.all(ppp["FX2"] == radar.carrier_hz + radar.bandwidth_hz / 2)
    assert np.allclose(ppp["FxRate"] * ppp["TXmt"], radar.bandwidth_hz, rtol=1e-12)
    errors = []
    for target in scene.truth["targets"]:
        at = ned_to_ecef(np.asarray(target["pos_ned"]), GEODETIC_ORIGIN)
        r = np.linalg.norm(ppp["TxPos"] - at, axis=1)
        near = np.argsort(r)[:41]
        delays = _crsd_delays_s(
            signal[near], ppp[near], pvp[near], radar.sample_rate_hz, 2 * r[near] / C_MPS
        )
        errors += list(delays * C_MPS / 2 - r[near])
    # Cramér-Rao bound of one pulse's range from its chirp in the simulator's noise:
    # c / (2 * 2 pi B_rms sqrt(2 SNR)), B_rms = B / sqrt(12), SNR = samples in the chirp
    # times the per-sample SNR of a unit target.
    snr = (
        radar.pulse_width_s
        * radar.sample_rate_hz
        * 10 ** (load_preset("ku-vehicle", scale=0.05).snr_db / 10)
    )
    crlb_m = C_MPS / 2 / (2 * np.pi * radar.bandwidth_hz / np.sqrt(12) * np.sqrt(2 * snr))
    bias, rms = float(np.mean(errors)), float(np.sqrt(np.mean(np.square(errors))))
    print(
        f"CRSD: {signal.shape[0]} vectors; antenna position vs the simulator's: max "
        f"{apc_error.max() * 1e3:.2f} mm; echo range vs truth over {len(errors)} pulses "
        f"(41 about each target's closest approach): mean {bias * 1e3:.2f} mm, rms "
        f"{rms * 1e3:.2f} mm (Cramér-Rao bound {crlb_m * 1e3:.2f} mm)"
    )
    assert apc_error.max() < 0.01
    assert abs(bias) < 4 * crlb_m / np.sqrt(len(errors))
    assert rms < 1.25 * crlb_m


def test_a_mavlink_run_states_the_ekf_origin_and_exports_to_sicd(
    scene: Scene, capsys: pytest.CaptureFixture[str]
) -> None:
    """The simulated autopilot's log (``nav.tlog``: ArduPilot's default streams, with
    GPS_GLOBAL_ORIGIN) replayed: the store's frame is the EKF origin, its positions are
    NED about it (the INS positions of the scenario frame, to the float32 of the wire),
    the targets are georeferenced within half a pixel and the SICD passes its check."""
    cfg = load_config(scene.out / "sim" / "sarmoco.toml")
    path = scene.out / "mavlink.zarr"
    replay_files(cfg, scene.out / "sim" / "radar.vrt", scene.out / "sim" / "nav.tlog", path, False)
    store = open_store(path)
    origin = schema.decode_geodetic_origin(store.attrs, "run")
    assert origin.source == "mavlink.GPS_GLOBAL_ORIGIN"
    assert store.attrs["geodetic_origin"]["height"] == schema.HEIGHT_MSL  # no undulation
    assert geodetic_to_ned(np.asarray(origin.lla), GEODETIC_ORIGIN) == pytest.approx(
        np.zeros(3), abs=0.01
    )
    nav = store.read("nav")
    vel = (nav["kind"] == schema.NAV_KIND_VELOCITY) & (nav["result"] == 0)
    apc = np.asarray(scene.truth["pulses"]["apc_ned"])
    ins = np.asarray(scene.truth["pulses"]["apc_ned"]) - scene.truth["scenario"]["lever_arm_m"]
    assert np.isfinite(nav["pos_ned"][vel]).all()
    span = np.ptp(apc, axis=0)
    assert np.all(np.ptp(nav["pos_ned"][vel], axis=0) >= 0.9 * span)  # the flown track
    assert np.linalg.norm(nav["pos_ned"][vel][0] - ins[0]) < 20.0  # scenario frame, not the run's
    motion = store.read("motion", ["t_ns", "pos_ned"])
    rows = np.searchsorted(np.asarray(scene.truth["pulses"]["t_ns"]), motion["t_ns"])
    ok = np.isfinite(motion["pos_ned"]).all(axis=1)
    assert ok.mean() > 0.9
    assert np.abs(motion["pos_ned"][ok] - apc[rows[ok]]).max() < 1e-3  # ideal INS: the true APC
    errors = _target_errors_m(Scene(store, scene.truth, scene.out))
    assert max(errors) < PIXEL_M / 2
    out = scene.out / "mavlink.nitf"
    assert main(["export", str(path), "--sicd", str(out)]) == 0, capsys.readouterr().err
    assert failures(skver.SicdConsistency.from_file, out, warnings=True) == []


def _cut_tlog(scene: Scene, keep: set[str], name: str) -> Path:
    """The simulated autopilot's log with only the messages ``keep``, replayed into a store
    named ``name``; the store's path."""
    src = mavutil.mavlink_connection(str(scene.out / "sim" / "nav.tlog"))
    records = []
    while (m := src.recv_match(type=list(keep))) is not None:
        records.append(tlog_record(m))
    (scene.out / f"{name}.tlog").write_bytes(b"".join(records))
    cfg = load_config(scene.out / "sim" / "sarmoco.toml")
    path = scene.out / f"{name}.zarr"
    replay_files(cfg, scene.out / "sim" / "radar.vrt", scene.out / f"{name}.tlog", path, False)
    return path


def test_ardupilot_default_streams_alone_give_positions_about_the_ekf_origin(
    scene: Scene,
) -> None:
    """The simulated autopilot's log cut to what ArduPilot streams unasked
    (GLOBAL_POSITION_INT, ATTITUDE, GPS_GLOBAL_ORIGIN, SYSTEM_TIME; 4 Hz): every focused
    pulse's ``motion/pos_ned`` is the true antenna position in the EKF origin's frame, to
    the 1 cm of the wire's degE7, the targets are georeferenced within half a pixel, and
    the SICD export takes it."""
    keep = {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "GPS_GLOBAL_ORIGIN", "SYSTEM_TIME"}
    path = _cut_tlog(scene, keep, "global")
    store = open_store(path)
    assert schema.decode_geodetic_origin(store.attrs, "run").source == "mavlink.GPS_GLOBAL_ORIGIN"
    assert max(_target_errors_m(Scene(store, scene.truth, scene.out))) < PIXEL_M / 2
    motion = store.read("motion", ["t_ns", "pos_ned"])
    ok = np.isfinite(motion["pos_ned"]).all(axis=1)
    apc = np.asarray(scene.truth["pulses"]["apc_ned"])
    rows = np.searchsorted(np.asarray(scene.truth["pulses"]["t_ns"]), motion["t_ns"][ok])
    err = np.linalg.norm(motion["pos_ned"][ok] - apc[rows], axis=1)
    print(f"GLOBAL_POSITION_INT only: {ok.sum()} of {ok.size} pulses with a position, "
          f"max {err.max():.4f} m from the true APC")  # fmt: skip
    assert ok.mean() > 0.9 and err.max() < 0.02
    assert main(["export", str(path), "--sicd", str(scene.out / "global.nitf")]) == 0


def test_global_position_alone_georeferences_the_targets(scene: Scene) -> None:
    """GLOBAL_POSITION_INT without GPS_GLOBAL_ORIGIN: the store's frame is the tangent plane
    at the first position (its altitude above MSL stated as used for the ellipsoid height),
    and every target is georeferenced within half a pixel of the simulator's place."""
    keep = {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "SYSTEM_TIME"}
    store = open_store(_cut_tlog(scene, keep, "global_only"))
    origin = schema.decode_geodetic_origin(store.attrs, "run")
    assert origin.source == "mavlink.GLOBAL_POSITION_INT" and not origin.ellipsoid_height
    assert store.attrs["geodetic_origin"]["height"] == schema.HEIGHT_MSL
    assert max(_target_errors_m(Scene(store, scene.truth, scene.out))) < PIXEL_M / 2


def test_the_checker_fails_a_sicd_whose_geometry_is_wrong(scene: Scene) -> None:
    """The consistency check can fail: the ARP velocity reversed (the SCPCOA computed from the
    original no longer matches it) is reported."""
    product = sicd_product(scene.store)
    xml = lxml.etree.ElementTree(lxml.etree.fromstring(lxml.etree.tostring(product.xml)))
    helper = sksicd.XmlHelper(xml)
    arp = helper.load("./{*}Position/{*}ARPPoly")
    arp[1] = -arp[1]
    helper.set("./{*}Position/{*}ARPPoly", arp)
    bad = scene.out / "bad.nitf"
    write_sicd(dataclasses.replace(product, xml=xml), bad)
    found = failures(skver.SicdConsistency.from_file, bad)
    assert any(f.startswith("check_scpcoa") for f in found), found


def test_export_refuses_a_store_without_absolute_position(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "noabs.zarr"
    Recorder(path, n_samples=8).close()
    status = main(["export", str(path), "--sicd", str(tmp_path / "x.nitf")])
    err = capsys.readouterr().err
    assert status == 2
    assert "geodetic_origin: no absolute position" in err and str(path) in err
    assert not (tmp_path / "x.nitf").exists()


def test_a_left_looking_scene_is_georeferenced_and_its_sicd_reversed(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    """Looking left: targets within half a pixel, and the SICD (columns reversed so that
    the grid normal points up) meets every check with side of track L."""
    left = _replayed_scene(tmp_path_factory.mktemp("left"), "left")
    assert max(_target_errors_m(left)) < PIXEL_M / 2
    product = sicd_product(left.store)
    out = left.out / "left.nitf"
    write_sicd(product, out)
    assert failures(skver.SicdConsistency.from_file, out, warnings=True) == []
    seg = segment_images(left.store)[0]
    assert np.array_equal(product.pixels, seg.image.data.T[:, ::-1])
    assert sksicd.XmlHelper(product.xml).load("./{*}SCPCOA/{*}SideOfTrack") == "L"


def test_no_north_up_image_about_a_point_the_ins_did_not_name(scene: Scene, tmp_path: Path) -> None:
    """An SBG INS gives geodetic positions and names no origin: the store's frame is the
    first fix's, a point of the daemon's choosing, so no north-up image is written (its
    north and east would be about that point) and the replay says why."""
    from sarmoco.products.northup import UNNAMED_ORIGIN, write_north_up_images

    store = tmp_path / "run.zarr"
    shutil.copytree(scene.store.path, store)
    assert not schema.decode_geodetic_origin(scene.store.attrs, "run").stated
    done = write_north_up_images(store)
    assert done.images == [] and done.lines() == [f"north-up image not written: {UNNAMED_ORIGIN}"]
    assert schema.NORTH_UP_GROUP not in open_store(store).root


def test_the_north_up_image_puts_every_target_at_its_ned_position(
    scene: Scene, tmp_path: Path
) -> None:
    """The scene replayed from its MAVLink log, whose autopilot names its EKF origin
    (GPS_GLOBAL_ORIGIN), and its segment resampled onto north/east (``sarmoco replay``
    writes it): coordinates NED about that origin, as the image's ``frame`` says; each
    simulated target's response (its peak found between pixels by upsampling) within 1 cm
    of where the simulator put it, converted to that origin (ideal INS)."""
    from sarmoco.geodesy import ned_to_geodetic
    from sarmoco.processing.metrics import point_target_metrics
    from sarmoco.processing.types import Image

    store = tmp_path / "run.zarr"
    sim = scene.out / "sim"
    done = subprocess.run(
        [sys.executable, "-m", "sarmoco", "replay", "--config", str(sim / "sarmoco.toml"),
         "--radar", str(sim / "radar.vrt"), "--nav", str(sim / "nav.tlog"), "--out", str(store),
         "--quiet"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    origin = schema.decode_geodetic_origin(open_store(store).attrs, "run")
    assert origin.stated and origin.source == "mavlink.GPS_GLOBAL_ORIGIN"
    (line,) = [x for x in done.stdout.splitlines() if "north-up image" in x]
    assert "north-up image 0 of" in line and "about the geodetic origin" in line
    group = open_store(store).root[f"{schema.NORTH_UP_GROUP}/{schema.north_up_name(0)}"]
    assert group.attrs["frame"] in line
    north, east = (np.asarray(group[name][...]) for name in schema.NORTH_UP_COORDS)
    data = np.asarray(group["data"][...])
    assert data.shape == (north.size, east.size) and f"{data.shape[0]} x {data.shape[1]}" in line
    misses = []
    for target in scene.truth["targets"]:
        at = geodetic_to_ned(
            ned_to_geodetic(np.asarray(target["pos_ned"]), GEODETIC_ORIGIN), origin.lla
        )
        m = point_target_metrics(
            Image(data, north, east, "ground"), (at[0], at[1]), 1.0, through_peak=True
        )
        assert m.position_error_m is not None
        misses.append(math.hypot(*m.position_error_m))
    print(f"north-up: targets' peaks {np.round(misses, 4).tolist()} m from their NED positions")
    assert len(misses) == 3
    assert max(misses) < 0.01
