"""CPHD (NGA.STND.0068, version 1.1.0) phase history in and out, written with sarkit.

The phase history here is in the FX domain, deramped per vector to a scene reference
point (SRP): a scatterer at range R from the antenna contributes
``exp(-j 4 pi f (R - R_srp) / c)`` (CPHD ``SGN = -1``; the AFRL GOTCHA convention, and what
our backprojection of a phase history takes, :mod:`sarmoco.processing.imaging`).

* :func:`from_gotcha` places a GOTCHA pass on the Earth and :func:`write_cphd` writes it.
  GOTCHA's files hold neither pulse times nor a geodetic origin: the scene frame (x east,
  y north, z up, origin the scene centre) is put at :data:`GOTCHA_NOMINAL_ORIGIN`, and the
  pulse times are the path length flown at :data:`GOTCHA_NOMINAL_SPEED_MPS` (both stated in
  the file's ``CollectionID/Parameter``); the deramp range of each pulse (the files' ``r0``)
  is kept exactly by a per-vector SRP on the line from the antenna to the scene centre.
* :func:`read_cphd` reads a CPHD back into the same form, and :func:`focus` backprojects it
  on a ground grid of the scene frame (east, north, up about the image-area reference
  point, IARP): ``sarmoco import-cphd FILE --out STORE`` (:mod:`sarmoco.app.import_cphd`)
  stores that image.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lxml.etree
import numpy as np
import numpy.typing as npt
import sarkit.cphd as skcphd

from sarmoco import __version__
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.drivers.gotcha import GotchaPass
from sarmoco.errors import DataFileError, RecorderError
from sarmoco.geodesy import ecef_to_geodetic, geodetic_to_ecef, ned_rotation
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    compressed_from_phase_history,
    facing_heading,
)
from sarmoco.processing.types import C_MPS, FloatArray, Image
from sarmoco.store.reader import RunStore

if TYPE_CHECKING:
    from sarmoco.daemon.config import Config
    from sarmoco.products.georeference import Georeference

CPHD_NS = "http://api.nsgreg.nga.mil/schema/cphd/1.1.0"
"""Namespace of the CPHD version written."""
GOTCHA_NOMINAL_ORIGIN = (39.78, -84.05, 250.0)
"""Latitude, longitude (deg) and height (m) given to GOTCHA's scene centre: nominal (the
files have none; near AFRL's Dayton, Ohio site), so the geometry is self-consistent but
not where the data were taken."""
GOTCHA_NOMINAL_SPEED_MPS = 100.0
"""Speed at which the GOTCHA path is taken to be flown to give pulse times (nominal)."""
_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""Permutation between NED and ENU components (its own inverse)."""


@dataclass(frozen=True)
class FxPhaseHistory:
    """A monostatic FX-domain phase history with its geometry in ECEF.

    Attributes
    ----------
    signal : ndarray of complex64, shape (V, S)
        Vector-major phase history, deramped to each vector's SRP.
    freq_hz : ndarray of float64, shape (S,)
        Uniform ascending frequencies of the samples, Hz.
    tx_time_s : ndarray of float64, shape (V,)
        Transmit time of each vector from ``collection_start``, s.
    apc_ecef_m : ndarray of float64, shape (V, 3)
        Antenna phase centre (stop-and-hop: transmit = receive), ECEF, m.
    srp_ecef_m : ndarray of float64, shape (V, 3)
        Scene reference point of each vector's deramp, ECEF, m.
    iarp_lla : tuple of 3 float
        Image-area reference point: latitude, longitude (deg), height (m).
    collection_start : datetime
        UTC time of ``tx_time_s = 0``.
    polarization : tuple of 2 str
        Transmit and receive polarization (``"H"``, ``"V"``...).
    notes : tuple of (str, str)
        Provenance stated in the file (``CollectionID/Parameter``).
    toa_span_s : tuple of 2 float or None
        Times of arrival saved about the SRP's, s (None: the widest the sampling allows,
        ``±1 / (2 FX_OVERSAMPLING SCSS)``).
    """

    signal: npt.NDArray[np.complex64]
    freq_hz: FloatArray
    tx_time_s: FloatArray
    apc_ecef_m: FloatArray
    srp_ecef_m: FloatArray
    iarp_lla: tuple[float, float, float]
    collection_start: datetime.datetime
    polarization: tuple[str, str] = ("H", "H")
    notes: tuple[tuple[str, str], ...] = ()
    toa_span_s: tuple[float, float] | None = None

    def toa_span(self) -> tuple[float, float]:
        """The TOA span saved (see ``toa_span_s``), s."""
        if self.toa_span_s is not None:
            return self.toa_span_s
        half = 0.5 / (FX_OVERSAMPLING * float(self.freq_hz[-1] - self.freq_hz[0]))
        half *= self.freq_hz.size - 1
        return (-half, half)

    def scene(self, ecef_m: FloatArray) -> FloatArray:
        """ECEF points (..., 3) → the scene frame: east, north, up about the IARP, m."""
        rot = ned_rotation(self.iarp_lla[0], self.iarp_lla[1])
        ned = (np.asarray(ecef_m) - geodetic_to_ecef(np.asarray(self.iarp_lla))) @ rot.T
        return np.asarray(ned @ _ENU_FROM_NED)

    def ecef(self, enu_m: FloatArray) -> FloatArray:
        """Scene-frame points (..., 3): east, north, up about the IARP, m → ECEF, m."""
        return _scene_to_ecef(enu_m, self.iarp_lla)

    @property
    def ref_range_m(self) -> FloatArray:
        """Deramp range of each vector, ``|APC - SRP|``, m."""
        return np.asarray(np.linalg.norm(self.apc_ecef_m - self.srp_ecef_m, axis=1))


def _scene_to_ecef(enu_m: FloatArray, origin: tuple[float, float, float]) -> FloatArray:
    rot = ned_rotation(origin[0], origin[1])
    return np.asarray(
        geodetic_to_ecef(np.asarray(origin)) + (np.asarray(enu_m) @ _ENU_FROM_NED) @ rot
    )


def from_gotcha(
    d: GotchaPass, origin: tuple[float, float, float] = GOTCHA_NOMINAL_ORIGIN
) -> FxPhaseHistory:
    """A GOTCHA pass on the Earth (see the module docstring for what is nominal)."""
    apc = _scene_to_ecef(d.apc_m, origin)
    centre = geodetic_to_ecef(np.asarray(origin))
    look = centre - apc
    srp = apc + look * (d.r0_m / np.linalg.norm(look, axis=1))[:, None]
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(d.apc_m, axis=0), axis=1))])
    return FxPhaseHistory(
        signal=np.ascontiguousarray(d.phase_history, dtype=np.complex64),
        freq_hz=np.asarray(d.freq_hz, dtype=np.float64),
        tx_time_s=path / GOTCHA_NOMINAL_SPEED_MPS,
        apc_ecef_m=apc,
        srp_ecef_m=srp,
        iarp_lla=origin,
        collection_start=datetime.datetime(2000, 1, 1, tzinfo=datetime.UTC),
        polarization=("H", "H"),
        notes=(
            ("source", "AFRL GOTCHA volumetric SAR data set (sarmoco.drivers.gotcha)"),
            ("geodetic_origin", f"nominal {origin}: the files give a local scene frame only"),
            ("tx_time", f"nominal: path length at {GOTCHA_NOMINAL_SPEED_MPS} m/s"),
            ("collection_start", "nominal: the files give no time"),
        ),
    )


_PVP_LAYOUT = (
    ("TxTime", 1), ("TxPos", 3), ("TxVel", 3), ("RcvTime", 1), ("RcvPos", 3), ("RcvVel", 3),
    ("SRPPos", 3), ("aFDOP", 1), ("aFRR1", 1), ("aFRR2", 1), ("FX1", 1), ("FX2", 1),
    ("TOA1", 1), ("TOA2", 1), ("TDTropoSRP", 1), ("SC0", 1), ("SCSS", 1),
)  # fmt: skip
"""Per-vector parameters written: name and size in 8-byte words, in file order."""
IMAGE_AREA_HALF_M = 50.0
"""Half side of the square image area stated about the IARP, m."""
GRID_M = 0.25
"""Spacing of the image grid stated over the image area, m."""
FX_OVERSAMPLING = 1.25
"""Ratio of the unambiguous time span ``1 / SCSS`` to the TOA span saved (CPHD asks >= 1.1)."""


@dataclass(frozen=True)
class SegmentEchoes:
    """The recorded echoes of one reference-track segment with their geometry.

    Attributes
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse (transmit) times, GPS ns.
    pos_m : ndarray of float64, shape (P, 3)
        Antenna phase centre in the run frame (NED), m: the trapezoid-integrated INS
        velocity of the antenna (:func:`~sarmoco.products.georeference.run_track`).
    echo : ndarray of complex64, shape (P, N)
        Raw echoes as the receiver delivered them (baseband, sample rate of the radar).
    corners_m : ndarray of float64, shape (4, 3)
        Corners of the segment image's ground grid, run frame, m.
    srp_m : ndarray of float64, shape (3,)
        Scene centre point: the centre pixel of the segment image, on the ground, run frame, m.
    georef : Georeference
        The store's run frame on the Earth.
    config : Config
        The configuration the store was made with.
    """

    t_ns: npt.NDArray[np.int64]
    pos_m: FloatArray
    echo: npt.NDArray[np.complex64]
    corners_m: FloatArray
    srp_m: FloatArray
    georef: Georeference
    config: Config


def segment_echoes(store: RunStore, segment: int = 0) -> SegmentEchoes:
    """The recorded echoes of one reference-track segment and where the antenna was.

    Raises
    ------
    RecorderError
        No absolute position, no raw echoes, or no such segment.
    """
    from sarmoco.daemon.config import parse_config
    from sarmoco.drivers.samples import to_complex64
    from sarmoco.products.georeference import georeference, grid_points, run_track, segment_image

    geo = georeference(store)
    cfg = parse_config(store.attrs["config"])
    seg = segment_image(store, segment)
    t, pos, _ = run_track(store)
    keep = (t >= seg.t0_ns) & (t <= seg.t1_ns)
    t, pos = t[keep], pos[keep]
    pulses = store.read("pulses", ["t_ns"])
    rows = np.searchsorted(pulses["t_ns"], t)
    if not np.array_equal(pulses["t_ns"][np.minimum(rows, pulses["t_ns"].size - 1)], t):
        raise RecorderError(f"{store.path}: motion rows without their recorded pulse")
    try:
        raw = store.read("pulses", ["echo"], int(rows[0]), int(rows[-1]) + 1)["echo"]
    except RecorderError as exc:
        raise RecorderError(f"{store.path}: no raw echoes recorded ({exc})") from exc
    echo = to_complex64(raw)[rows - rows[0]]
    pts = grid_points(seg.image, seg.track, cfg.geometry.height_m)
    return SegmentEchoes(
        t_ns=t,
        pos_m=pos,
        echo=echo,
        corners_m=pts[[0, 0, -1, -1], [0, -1, 0, -1]],
        srp_m=pts[pts.shape[0] // 2, pts.shape[1] // 2],
        georef=geo,
        config=cfg,
    )


def from_store(store: RunStore, segment: int = 0) -> FxPhaseHistory:
    """The recorded echoes of one reference-track segment as a phase history on the Earth.

    Each pulse is range compressed (unweighted) and turned into its range spectrum
    deramped to the segment's scene centre point (SRP: the centre pixel of its image, on
    the ground) from the antenna position the INS gave (:func:`segment_echoes`, the
    position the INS-only compensation uses). The data are thus compensated to the SRP by
    the INS; the PVP positions are those antenna positions, in ECEF through the store's
    georeference. The TOA swath saved is the segment image's slant-range extent about the
    SRP.

    Raises
    ------
    RecorderError
        No absolute position, no raw echoes, or no such segment.
    """
    from sarmoco.processing import rangecomp
    from sarmoco.processing.imaging.phase_history import phase_history_from_compressed

    seg = segment_echoes(store, segment)
    t, pos, srp, geo = seg.t_ns, seg.pos_m, seg.srp_m, seg.georef
    radar = seg.config.radar.params()
    ref = np.linalg.norm(pos - srp, axis=1)
    rc = rangecomp.compress(radar, seg.echo)
    ph, freq = phase_history_from_compressed(
        rc, rangecomp.range_axis_m(radar), radar.carrier_hz, radar.bandwidth_hz, ref
    )
    extent = np.linalg.norm(pos[:, None, :] - seg.corners_m[None], axis=2) - ref[:, None]
    apc = geo.ecef(pos)
    start = gps_utc(int(t[0]), seg.config.ins.gps_minus_utc_s)
    return FxPhaseHistory(
        signal=np.ascontiguousarray(ph, dtype=np.complex64),
        freq_hz=freq,
        tx_time_s=(t - t[0]) * 1e-9,
        apc_ecef_m=apc,
        srp_ecef_m=np.tile(geo.ecef(srp), (t.size, 1)),
        iarp_lla=tuple(float(v) for v in geo.geodetic(srp)),  # type: ignore[arg-type]
        collection_start=start,
        polarization=("UNSPECIFIED", "UNSPECIFIED"),
        notes=(
            ("source", f"{store.path.name}: segment {segment}, {t.size} pulses"),
            ("compensation", "deramped to the SRP from the INS-integrated antenna track"),
            *geo.parameters(),
        ),
        toa_span_s=(2.0 * float(extent.min()) / C_MPS, 2.0 * float(extent.max()) / C_MPS),
    )


def gps_utc(t_ns: int, gps_minus_utc_s: int) -> datetime.datetime:
    """A GPS time (ns) as a UTC datetime (µs)."""
    unix_ns = gps_ns_to_unix_ns(t_ns, gps_minus_utc_s)
    epoch = datetime.datetime(1970, 1, 1, tzinfo=datetime.UTC)
    return epoch + datetime.timedelta(microseconds=unix_ns // 1000)


def _pvp_xml() -> dict[str, Any]:
    out, offset = {}, 0
    xyz = np.dtype([("X", "f8"), ("Y", "f8"), ("Z", "f8")])
    for name, size in _PVP_LAYOUT:
        out[name] = {"Offset": offset, "Size": size, "dtype": xyz if size == 3 else np.dtype("f8")}
        offset += size
    return out


def scene_xml(iarp_lla: tuple[float, float, float]) -> dict[str, Any]:
    """The ``SceneCoordinates`` (CPHD's, which CRSD shares) about an image-area reference
    point (latitude, longitude in deg, height in m): a square image area of
    ``2 IMAGE_AREA_HALF_M`` on the plane tangent to the Earth there (east, north)."""
    iarp = geodetic_to_ecef(np.asarray(iarp_lla))
    rot = ned_rotation(iarp_lla[0], iarp_lla[1])
    half = IMAGE_AREA_HALF_M
    n_grid = round(2 * half / GRID_M) + 1
    square = [(-half, -half), (-half, half), (half, half), (half, -half)]
    corners = [_scene_to_ecef(np.array([x, y, 0.0]), iarp_lla) for x, y in square]
    return {
        "EarthModel": "WGS_84",
        "IARP": {"ECF": iarp, "LLH": np.asarray(iarp_lla)},
        "ReferenceSurface": {"Planar": {"uIAX": rot[1], "uIAY": rot[0]}},
        "ImageArea": {"X1Y1": [-half, -half], "X2Y2": [half, half]},
        "ImageAreaCornerPoints": np.array([ecef_to_geodetic(c)[:2] for c in corners]),
        "ImageGrid": {
            "IARPLocation": [n_grid // 2, n_grid // 2],
            "IAXExtent": {"LineSpacing": GRID_M, "FirstLine": 0, "NumLines": n_grid},
            "IAYExtent": {"SampleSpacing": GRID_M, "FirstSample": 0, "NumSamples": n_grid},
        },
    }


def _xml(ph: FxPhaseHistory, pvps: npt.NDArray[Any], core_name: str) -> Any:
    v, s = ph.signal.shape
    fx1, fx2 = float(ph.freq_hz[0]), float(ph.freq_hz[-1])
    toa1, toa2 = ph.toa_span()
    srp_fixed = bool(np.all(ph.srp_ecef_m == ph.srp_ecef_m[0]))
    duration = float(ph.tx_time_s[-1])
    root = lxml.etree.Element(f"{{{CPHD_NS}}}CPHD")
    cphd = skcphd.ElementWrapper(root)
    cphd["CollectionID"] = {
        "CollectorName": "sarmoco",
        "CoreName": core_name,
        "CollectType": "MONOSTATIC",
        "RadarMode": {"ModeType": "SPOTLIGHT"},
        "Classification": "UNCLASSIFIED",
        "ReleaseInfo": "UNRESTRICTED",
        "Parameter": [(k, val) for k, val in (("writer", f"sarmoco {__version__}"), *ph.notes)],
    }
    cphd["Global"] = {
        "DomainType": "FX",
        "SGN": -1,
        "Timeline": {
            "CollectionStart": ph.collection_start,
            "TxTime1": float(ph.tx_time_s[0]),
            "TxTime2": duration,
        },
        "FxBand": {"FxMin": fx1, "FxMax": fx2},
        "TOASwath": {"TOAMin": toa1, "TOAMax": toa2},
    }
    cphd["SceneCoordinates"] = scene_xml(ph.iarp_lla)
    cphd["Data"] = {
        "SignalArrayFormat": "CF8",
        "NumBytesPVP": pvps.dtype.itemsize,
        "NumCPHDChannels": 1,
        "Channel": [
            {
                "Identifier": "1",
                "NumVectors": v,
                "NumSamples": s,
                "SignalArrayByteOffset": 0,
                "PVPArrayByteOffset": 0,
            }
        ],
        "NumSupportArrays": 0,
    }
    cphd["Channel"] = {
        "RefChId": "1",
        "FXFixedCPHD": True,
        "TOAFixedCPHD": True,
        "SRPFixedCPHD": srp_fixed,
        "Parameters": [
            {
                "Identifier": "1",
                "RefVectorIndex": v // 2,
                "FXFixed": True,
                "TOAFixed": True,
                "SRPFixed": srp_fixed,
                "Polarization": {"TxPol": ph.polarization[0], "RcvPol": ph.polarization[1]},
                "FxC": (fx1 + fx2) / 2.0,
                "FxBW": fx2 - fx1,
                "TOASaved": toa2 - toa1,
                "DwellTimes": {"CODId": "cod", "DwellId": "dwell"},
            }
        ],
    }
    cphd["PVP"] = _pvp_xml()
    cphd["Dwell"] = {
        "NumCODTimes": 1,
        "CODTime": [{"Identifier": "cod", "CODTimePoly": np.array([[duration / 2.0]])}],
        "NumDwellTimes": 1,
        "DwellTime": [{"Identifier": "dwell", "DwellTimePoly": np.array([[duration]])}],
    }
    tree = root.getroottree()
    root.append(skcphd.compute_reference_geometry(tree, pvps))
    return tree


def _pvps(ph: FxPhaseHistory, dtype: np.dtype[Any]) -> npt.NDArray[Any]:
    v, s = ph.signal.shape
    t = ph.tx_time_s
    vel = np.gradient(ph.apc_ecef_m, t, axis=0)
    pvp = np.zeros(v, dtype=dtype)
    pvp["TxTime"] = t
    pvp["TxPos"] = ph.apc_ecef_m
    pvp["TxVel"] = vel
    pvp["RcvTime"] = t + 2.0 * ph.ref_range_m / C_MPS
    pvp["RcvPos"] = ph.apc_ecef_m
    pvp["RcvVel"] = vel
    pvp["SRPPos"] = ph.srp_ecef_m
    los = ph.apc_ecef_m - ph.srp_ecef_m
    rdot = np.sum(vel * los, axis=1) / np.linalg.norm(los, axis=1)
    pvp["aFDOP"] = -2.0 * rdot / C_MPS
    pvp["FX1"] = ph.freq_hz[0]
    pvp["FX2"] = ph.freq_hz[-1]
    pvp["SC0"] = ph.freq_hz[0]
    pvp["SCSS"] = (ph.freq_hz[-1] - ph.freq_hz[0]) / (s - 1)
    pvp["TOA1"], pvp["TOA2"] = ph.toa_span()
    return pvp


def write_cphd(ph: FxPhaseHistory, path: Path, core_name: str = "sarmoco") -> None:
    """Write one channel of FX-domain phase history as CPHD 1.1.0."""
    placeholder = lxml.etree.Element(f"{{{CPHD_NS}}}CPHD")
    layout = skcphd.ElementWrapper(placeholder)
    layout["Data"] = {"NumBytesPVP": 8 * sum(size for _, size in _PVP_LAYOUT)}
    layout["PVP"] = _pvp_xml()
    pvps = _pvps(ph, skcphd.get_pvp_dtype(placeholder.getroottree()))
    xml = _xml(ph, pvps, core_name)
    meta = skcphd.Metadata(xmltree=xml)
    with path.open("wb") as f, skcphd.Writer(f, meta) as writer:
        writer.write_signal("1", ph.signal)
        writer.write_pvp("1", pvps)


def read_cphd(path: Path) -> FxPhaseHistory:
    """Read the first channel of a monostatic FX-domain CPHD (SGN -1, uniform samples).

    Raises
    ------
    DataFileError
        Naming the file and the field: not readable, not FX domain, SGN not -1, or a
        channel whose sample frequencies differ from vector to vector.
    """
    try:
        with path.open("rb") as f, skcphd.Reader(f) as reader:
            xml = reader.metadata.xmltree
            ch = xml.findtext("{*}Data/{*}Channel/{*}Identifier")
            signal, pvp = reader.read_channel(ch)
    except (OSError, ValueError, KeyError, lxml.etree.LxmlError) as exc:
        raise DataFileError(f"{path}: not a readable CPHD ({exc})") from exc
    helper = skcphd.XmlHelper(xml)
    if helper.load("{*}Global/{*}DomainType") != "FX":
        raise DataFileError(f"{path}: Global/DomainType is not FX")
    if helper.load("{*}Global/{*}SGN") != -1:
        raise DataFileError(f"{path}: Global/SGN is not -1")
    if np.ptp(pvp["SC0"]) or np.ptp(pvp["SCSS"]):
        raise DataFileError(f"{path}: PVP SC0/SCSS vary between vectors")
    n = signal.shape[1]
    freq = pvp["SC0"][0] + np.arange(n) * pvp["SCSS"][0]
    tx, rcv = (
        helper.load("{*}Channel/{*}Parameters/{*}Polarization/{*}TxPol"),
        helper.load("{*}Channel/{*}Parameters/{*}Polarization/{*}RcvPol"),
    )
    llh = helper.load("{*}SceneCoordinates/{*}IARP/{*}LLH")
    return FxPhaseHistory(
        signal=np.asarray(signal, dtype=np.complex64),
        freq_hz=np.asarray(freq, dtype=np.float64),
        tx_time_s=np.asarray(pvp["TxTime"], dtype=np.float64),
        apc_ecef_m=0.5 * (pvp["TxPos"] + pvp["RcvPos"]),
        srp_ecef_m=np.asarray(pvp["SRPPos"], dtype=np.float64),
        iarp_lla=(float(llh[0]), float(llh[1]), float(llh[2])),
        collection_start=helper.load("{*}Global/{*}Timeline/{*}CollectionStart"),
        polarization=(str(tx), str(rcv)),
    )


def focus(ph: FxPhaseHistory, size: int, pixel_m: float) -> Image:
    """Backprojection of a phase history on a ``size`` x ``size`` ground grid of the scene
    frame centred on the IARP, axis 1 along the mean look direction, ``pixel_m`` apart."""
    grid = PlaneGrid.centred((0.0, 0.0, 0.0), size, size, pixel_m, pixel_m, grid_heading(ph))
    rc, r_axis, fc = compressed_from_phase_history(ph.signal, ph.freq_hz)
    apc = ph.scene(ph.apc_ecef_m)
    return backproject(rc, r_axis, apc, C_MPS / fc, grid, ref_range_m=ph.ref_range_m)


def grid_heading(ph: FxPhaseHistory) -> float:
    """Heading of :func:`focus`'s grid: axis 1 along the mean look direction to the IARP
    (axis 0 from east toward north), rad."""
    return facing_heading(ph.scene(ph.apc_ecef_m), (0.0, 0.0, 0.0))
