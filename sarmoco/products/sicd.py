"""SICD (NGA.STND.0024, version 1.4.0) of our focused images, written with sarkit.

A store's SICD (:func:`sicd_product`) holds the tiles of one reference-track segment joined
along track (:func:`~sarmoco.products.georeference.segment_image`); a phase history's
(:func:`spotlight_product`, e.g. GOTCHA through CPHD) its backprojection on a ground grid
about the image-area reference point. The pixels are ours, unchanged: for a store
SICD rows are our axis 1 (ground range y), columns our axis 0 (along-track x; reversed for
a left-looking radar, so that the grid normal points away from the Earth), i.e. the SICD
array is ``data.T`` (``data.T[:, ::-1]`` looking left).

The geometry the metadata states (docs/methods.md §1, :mod:`sarmoco.products.georeference`):

* ``Grid``: ImagePlane GROUND, Type PLANE (a uniformly sampled ground grid, backprojected),
  Row along the imaging-frame y, Col along x, both in ECEF; the spatial-frequency support
  of the range chirp (2 B / c) and of the azimuth beam ((4 / λ) sin(θ/2)) projected on the
  ground at the scene centre point (SCP); TimeCOAPoly: the time at which the reference
  track passes broadside of a pixel (zero Doppler after motion compensation).
* ``Position/ARPPoly``: the reference track (the data are motion-compensated to it), a
  line in ECEF.
* ``ImageFormation``: ImageFormAlgo OTHER (time-domain backprojection), with the INS
  motion compensation and the autofocus in ``Processing`` elements.

A spotlight image (:func:`spotlight_product`) has rows along the grid's axis 1 (the mean
look direction) and columns along its axis 0 reversed (so the normal points up), i.e.
``data.T[:, ::-1]``; its TimeCOAPoly is the aperture's middle, its ARPPoly a fifth-order
fit to the antenna positions, its bandwidths those of the band and of the azimuth span.
"""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lxml.etree
import numpy as np
import numpy.typing as npt
import sarkit.sicd as sksicd
from scipy.signal import get_window

from sarmoco import __version__
from sarmoco.daemon.config import Config, parse_config
from sarmoco.geodesy import ecef_to_geodetic
from sarmoco.processing.types import FloatArray, Image
from sarmoco.products.cphd import FxPhaseHistory, gps_utc
from sarmoco.products.georeference import (
    Georeference,
    SegmentImage,
    georeference,
    grid_points,
    segment_image,
)
from sarmoco.store.reader import RunStore

SICD_NS = "urn:SICD:1.4.0"
"""Namespace of the SICD version written."""
SPEED_OF_LIGHT_MPS = 299_792_458.0


@dataclass(frozen=True)
class SicdProduct:
    """A SICD ready to write: its XML and its pixel array.

    Attributes
    ----------
    xml : lxml.etree.ElementTree
        The SICD XML.
    pixels : ndarray of complex64, shape (NumRows, NumCols)
        The image as SICD orders it (see the module docstring).
    source : str
        What it holds, for messages.
    """

    xml: lxml.etree._ElementTree
    pixels: npt.NDArray[np.complex64]
    source: str


@dataclass(frozen=True)
class _Description:
    """Everything a SICD states, computed by a product (strip or spotlight)."""

    core_name: str
    mode: str
    scp_px: tuple[int, int]
    shape: tuple[int, int]
    scp_ecf: FloatArray
    scp_llh: FloatArray
    corners: FloatArray
    row: dict[str, Any]
    col: dict[str, Any]
    time_coa_poly: FloatArray
    start: datetime.datetime
    n_pulses: int
    ipp_poly: FloatArray
    arp_poly: FloatArray
    band_hz: tuple[float, float]
    waveform: dict[str, Any]
    polarization: tuple[str, str]
    t_end_proc: float
    az_autofocus: str
    processing: list[dict[str, Any]]


def irw_factor(window: str) -> float:
    """3 dB width of the impulse response of a weighting, in units of 1 / bandwidth.

    The weighting is scipy's window of that name (as the range compression applies it;
    ``"none"``: uniform, 0.8859); the width is measured on its transform, 64 times
    zero-padded, with the crossing interpolated linearly.
    """
    n, pad = 256, 64
    w = np.ones(n) if window == "none" else get_window(window, n, fftbins=False)
    spec = np.abs(np.fft.fft(w, n * pad))
    spec /= spec[0]
    half = 1.0 / math.sqrt(2.0)
    k = int(np.argmax(spec < half))
    frac = (spec[k - 1] - half) / (spec[k - 1] - spec[k])
    return 2.0 * (k - 1 + frac) / pad


def _grid_dim(uvect: FloatArray, ss: float, bw: float, kctr: float, window: str) -> dict[str, Any]:
    return {
        "UVectECF": uvect,
        "SS": ss,
        "ImpRespWid": irw_factor(window) / bw,
        "Sgn": -1,
        "ImpRespBW": bw,
        "KCtr": kctr,
        "DeltaK1": -bw / 2.0,
        "DeltaK2": bw / 2.0,
        "DeltaKCOAPoly": np.zeros((1, 1)),
        "WgtType": {"WindowName": "UNIFORM" if window == "none" else window.upper()},
    }


def _processing(cfg: Config, store: RunStore, geo: Georeference) -> list[dict[str, Any]]:
    """``ImageFormation/Processing``: the INS motion compensation, the autofocus and the
    georeference (the frame and origin the geometry went through)."""
    af = cfg.autofocus
    applied = 0
    if "autofocus" in store.tables() and store.committed("autofocus"):
        applied = int(store.read("autofocus", ["applied"])["applied"].sum())
    return [
        {
            "Type": "INS motion compensation (D_los from the integrated INS velocity)",
            "Applied": True,
            "Parameter": [
                ("order", str(cfg.mocomp.order)),
                ("along_track", str(cfg.mocomp.along_track)),
                ("lever_arm_m", ",".join(f"{v:g}" for v in cfg.ins.lever_arm_m)),
            ],
        },
        {
            "Type": "sliding-subaperture autofocus",
            "Applied": bool(af.enabled and applied > 0),
            "Parameter": [
                ("subaperture_s", f"{af.subaperture_s:g}"),
                ("hop_s", f"{af.hop_s:g}"),
                ("subapertures_applied", str(applied)),
            ],
        },
        {
            "Type": "georeference (run frame to WGS-84 through the INS positions)",
            "Applied": True,
            "Parameter": list(geo.parameters()),
        },
    ]


def sicd_product(store: RunStore, segment: int = 0) -> SicdProduct:
    """The SICD of one reference-track segment of a store.

    Parameters
    ----------
    store : RunStore
        A store with image tiles and an absolute position.
    segment : int
        Which segment (0: the first).

    Raises
    ------
    RecorderError
        No absolute position (``geodetic_origin``), no such segment, or an image that is
        not in the ground plane.
    """
    geo = georeference(store)
    cfg = parse_config(store.attrs["config"])
    seg = segment_image(store, segment)
    pixels = seg.image.data.T
    if cfg.geometry.look_side == "left":
        pixels = pixels[:, ::-1]
    source = f"tiles {seg.tiles[0]}..{seg.tiles[-1]}"
    return SicdProduct(
        _sicd_xml(_strip(store, cfg, geo, seg)),
        np.ascontiguousarray(pixels, dtype=np.complex64),
        source,
    )


def _strip(store: RunStore, cfg: Config, geo: Georeference, seg: SegmentImage) -> _Description:
    radar = cfg.radar.params()
    image, track = seg.image, seg.track
    left = cfg.geometry.look_side == "left"
    sign = -1.0 if left else 1.0
    n0, n1 = image.data.shape
    rows, cols = n1, n0
    scp_px = (rows // 2, cols // 2)
    pts = grid_points(image, track, cfg.geometry.height_m)

    def pixel(row: int, col: int) -> FloatArray:
        """Run-frame position of SICD pixel (row, col), m."""
        return np.asarray(pts[cols - 1 - col if left else col, row])

    last = (rows - 1, cols - 1)
    corner_px = [(0, 0), (0, last[1]), last, (last[0], 0)]  # FRFC, FRLC, LRLC, LRFC
    t0_s = (seg.t0_ns - track.t0_ns) * 1e-9  # collect start on the track's clock
    duration = (seg.t1_ns - seg.t0_ns) * 1e-9
    x_scp = float(image.axis0_m[cols - 1 - scp_px[1] if left else scp_px[1]])
    arp0 = geo.ecef(track.origin_ned + track.x_hat * track.v0_mps * t0_s)
    arp_vel = geo.ecef_vector(track.x_hat * track.v0_mps)
    y_scp = float(image.axis1_m[scp_px[0]])
    cos_graze = y_scp / math.hypot(y_scp, cfg.geometry.height_m)
    k_c = 2.0 * radar.carrier_hz / SPEED_OF_LIGHT_MPS
    row_bw = 2.0 * radar.bandwidth_hz / SPEED_OF_LIGHT_MPS * cos_graze
    beam = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    col_bw = 4.0 / radar.wavelength_m * math.sin(beam / 2.0)
    ss0, ss1 = image.spacing_m
    f_lo = radar.carrier_hz - radar.bandwidth_hz / 2.0
    window = cfg.imaging.window
    return _Description(
        core_name=f"{store.path.name}:tile{seg.tiles[0]}",
        mode="STRIPMAP",
        scp_px=scp_px,
        shape=(rows, cols),
        scp_ecf=geo.ecef(pixel(*scp_px)),
        scp_llh=geo.geodetic(pixel(*scp_px)),
        corners=np.array([geo.geodetic(pixel(*rc))[:2] for rc in corner_px]),
        row=_grid_dim(geo.ecef_vector(track.y_hat), ss1, row_bw, k_c * cos_graze, window),
        col=_grid_dim(geo.ecef_vector(sign * track.x_hat), ss0, col_bw, 0.0, "none"),
        time_coa_poly=np.array([[x_scp / track.v0_mps - t0_s, sign / track.v0_mps]]),
        start=gps_utc(seg.t0_ns, cfg.ins.gps_minus_utc_s),
        n_pulses=math.floor(duration * radar.prf_hz) + 1,
        ipp_poly=np.array([0.0, radar.prf_hz]),
        arp_poly=np.stack([arp0, arp_vel]),
        band_hz=(f_lo, f_lo + radar.bandwidth_hz),
        waveform={
            "TxPulseLength": radar.pulse_width_s,
            "TxRFBandwidth": radar.bandwidth_hz,
            "TxFreqStart": f_lo,
            "TxFMRate": radar.bandwidth_hz / radar.pulse_width_s,
            "RcvDemodType": "CHIRP",
            "ADCSampleRate": radar.sample_rate_hz,
        },
        polarization=("UNKNOWN", "UNKNOWN"),
        t_end_proc=duration,
        az_autofocus="SV" if cfg.autofocus.enabled else "NO",
        processing=_processing(cfg, store, geo),
    )


def spotlight_product(ph: FxPhaseHistory, image: Image, heading_rad: float) -> SicdProduct:
    """The SICD of a phase history's backprojection (:func:`sarmoco.products.cphd.focus`).

    Parameters
    ----------
    ph : FxPhaseHistory
        The phase history (geometry in ECEF, times from its collection start).
    image : Image
        Its image on a centred ground grid of the IARP's east-north-up frame.
    heading_rad : float
        The grid's heading (axis 0 from east toward north), rad.
    """
    n0, n1 = image.data.shape
    rows, cols = n1, n0
    scp_px = (rows // 2, cols // 2)
    e0 = np.array([math.cos(heading_rad), math.sin(heading_rad), 0.0])
    e1 = np.array([-math.sin(heading_rad), math.cos(heading_rad), 0.0])

    def pixel(row: int, col: int) -> FloatArray:
        """ECEF position of SICD pixel (row, col), m (columns run along -axis 0)."""
        enu = image.axis0_m[cols - 1 - col] * e0 + image.axis1_m[row] * e1
        return ph.ecef(enu)

    last = (rows - 1, cols - 1)
    corner_px = [(0, 0), (0, last[1]), last, (last[0], 0)]
    scp = pixel(*scp_px)
    t = ph.tx_time_s
    apc = ph.apc_ecef_m
    look = scp - apc[apc.shape[0] // 2]
    cos_graze = float(np.linalg.norm(look - np.dot(look, _unit(scp)) * _unit(scp)))
    cos_graze /= float(np.linalg.norm(look))
    f_lo, f_hi = float(ph.freq_hz[0]), float(ph.freq_hz[-1])
    f_c, bandwidth = (f_lo + f_hi) / 2.0, f_hi - f_lo
    enu_apc = ph.scene(apc)
    az = np.unwrap(np.arctan2(enu_apc[:, 1], enu_apc[:, 0]))
    span = abs(float(az[-1] - az[0])) * t.size / max(t.size - 1, 1)
    k_c = 2.0 * f_c / SPEED_OF_LIGHT_MPS
    rate = (t.size - 1) / float(t[-1] - t[0])
    e0_ecef, e1_ecef = ph.ecef(e0) - ph.ecef(np.zeros(3)), ph.ecef(e1) - ph.ecef(np.zeros(3))
    tx, rcv = (_sicd_polarization(p) for p in ph.polarization)
    return SicdProduct(
        _sicd_xml(
            _Description(
                core_name="phase history",
                mode="SPOTLIGHT",
                scp_px=scp_px,
                shape=(rows, cols),
                scp_ecf=scp,
                scp_llh=ecef_to_geodetic(scp),
                corners=np.array([ecef_to_geodetic(pixel(*rc))[:2] for rc in corner_px]),
                row=_grid_dim(
                    e1_ecef,
                    image.spacing_m[1],
                    k_c * bandwidth / f_c * cos_graze,
                    k_c * cos_graze,
                    "none",
                ),
                col=_grid_dim(-e0_ecef, image.spacing_m[0], k_c * cos_graze * span, 0.0, "none"),
                time_coa_poly=np.array([[float(t[0] + t[-1]) / 2.0]]),
                start=ph.collection_start,
                n_pulses=t.size,
                ipp_poly=np.array([-rate * float(t[0]), rate]),
                arp_poly=np.asarray(np.polynomial.polynomial.polyfit(t, apc, 5), np.float64),
                band_hz=(f_lo, f_hi),
                waveform={"TxRFBandwidth": bandwidth, "TxFreqStart": f_lo},
                polarization=(tx, "UNKNOWN" if "UNKNOWN" in (tx, rcv) else f"{tx}:{rcv}"),
                t_end_proc=float(t[-1]),
                az_autofocus="NO",
                processing=[{"Type": "backprojection of the FX phase history", "Applied": True}],
            )
        ),
        np.ascontiguousarray(image.data.T[:, ::-1], dtype=np.complex64),
        f"{t.size} vectors",
    )


def _sicd_polarization(cphd_pol: str) -> str:
    """A CPHD channel's TxPol or RcvPol as SICD states one polarization: ``UNKNOWN`` for
    CPHD's ``UNSPECIFIED`` (SICD has no such value), the others as they are."""
    return "UNKNOWN" if cphd_pol == "UNSPECIFIED" else cphd_pol


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v))


def _sicd_xml(d: _Description) -> Any:
    rows, cols = d.shape
    collect_s = float(d.n_pulses / d.ipp_poly[1])  # the last pulse's interval ends here
    root = lxml.etree.Element(f"{{{SICD_NS}}}SICD")
    sicd = sksicd.ElementWrapper(root)
    sicd["CollectionInfo"] = {
        "CollectorName": "sarmoco",
        "CoreName": d.core_name,
        "CollectType": "MONOSTATIC",
        "RadarMode": {"ModeType": d.mode},
        "Classification": "UNCLASSIFIED",
    }
    sicd["ImageCreation"] = {
        "Application": f"sarmoco {__version__}",
        "DateTime": datetime.datetime.now(datetime.UTC),
        "Profile": "sarmoco export",
    }
    sicd["ImageData"] = {
        "PixelType": "RE32F_IM32F",
        "NumRows": rows,
        "NumCols": cols,
        "FirstRow": 0,
        "FirstCol": 0,
        "FullImage": {"NumRows": rows, "NumCols": cols},
        "SCPPixel": np.array(d.scp_px),
    }
    sicd["GeoData"] = {
        "EarthModel": "WGS_84",
        "SCP": {"ECF": d.scp_ecf, "LLH": d.scp_llh},
        "ImageCorners": d.corners,
    }
    sicd["Grid"] = {
        "ImagePlane": "GROUND",
        "Type": "PLANE",
        "TimeCOAPoly": d.time_coa_poly,
        "Row": d.row,
        "Col": d.col,
    }
    sicd["Timeline"] = {
        "CollectStart": d.start,
        "CollectDuration": collect_s,
        "IPP": {
            "@size": 1,
            "Set": [
                {
                    "@index": 1,
                    "TStart": float(-d.ipp_poly[0] / d.ipp_poly[1]),
                    "TEnd": collect_s,
                    "IPPStart": 0,
                    "IPPEnd": d.n_pulses - 1,
                    "IPPPoly": d.ipp_poly,
                }
            ],
        },
    }
    sicd["Position"] = {"ARPPoly": d.arp_poly}
    sicd["RadarCollection"] = {
        "TxFrequency": {"Min": d.band_hz[0], "Max": d.band_hz[1]},
        "Waveform": {"@size": 1, "WFParameters": [{"@index": 1, **d.waveform}]},
        "TxPolarization": d.polarization[0],
        "RcvChannels": {
            "@size": 1,
            "ChanParameters": [{"@index": 1, "TxRcvPolarization": d.polarization[1]}],
        },
    }
    sicd["ImageFormation"] = {
        "RcvChanProc": {"NumChanProc": 1, "ChanIndex": [1]},
        "TxRcvPolarizationProc": d.polarization[1],
        "TStartProc": 0.0,
        "TEndProc": d.t_end_proc,
        "TxFrequencyProc": {"MinProc": d.band_hz[0], "MaxProc": d.band_hz[1]},
        "ImageFormAlgo": "OTHER",
        "STBeamComp": "NO",
        "ImageBeamComp": "NO",
        "AzAutofocus": d.az_autofocus,
        "RgAutofocus": "NO",
        "Processing": d.processing,
    }
    tree = root.getroottree()
    root.append(sksicd.compute_scp_coa(tree))
    return tree


def write_sicd(product: SicdProduct, path: Path) -> None:
    """Write a SICD NITF (unclassified, one image segment as sarkit sizes it)."""
    sec = sksicd.NitfSecurityFields(clas="U")
    meta = sksicd.NitfMetadata(
        xmltree=product.xml,
        file_header_part=sksicd.NitfFileHeaderPart(ostaid="sarmoco", security=sec),
        im_subheader_part=sksicd.NitfImSubheaderPart(isorce="sarmoco", security=sec),
        de_subheader_part=sksicd.NitfDeSubheaderPart(security=sec),
    )
    with path.open("wb") as f, sksicd.NitfWriter(f, meta) as writer:
        writer.write_image(product.pixels)
