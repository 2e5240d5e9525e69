"""SICD (NGA.STND.0024, version 1.4.0) of a store's focused images, written with sarkit.

One SICD holds the tiles of one reference-track segment joined along track
(:func:`~sarmoco.daemon.georeference.segment_images`). The pixels are ours, unchanged:
SICD rows are our axis 1 (ground range y), columns our axis 0 (along-track x; reversed for
a left-looking radar, so that the grid normal points away from the Earth), i.e. the SICD
array is ``data.T`` (``data.T[:, ::-1]`` looking left).

The geometry the metadata states (docs/methods.md §1, :mod:`sarmoco.daemon.georeference`):

* ``Grid``: ImagePlane GROUND, Type PLANE (a uniformly sampled ground grid, backprojected),
  Row along the imaging-frame y, Col along x, both in ECEF; the spatial-frequency support
  of the range chirp (2 B / c) and of the azimuth beam ((4 / λ) sin(θ/2)) projected on the
  ground at the scene centre point (SCP); TimeCOAPoly: the time at which the reference
  track passes broadside of a pixel (zero Doppler after motion compensation).
* ``Position/ARPPoly``: the reference track (the data are motion-compensated to it), a
  line in ECEF.
* ``ImageFormation``: ImageFormAlgo OTHER (time-domain backprojection), with the INS
  motion compensation and the autofocus in ``Processing`` elements.
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
from sarmoco.daemon.focuser import radar_params
from sarmoco.daemon.georeference import (
    Georeference,
    SegmentImage,
    georeference,
    grid_points,
    segment_images,
)
from sarmoco.daemon.store import RunStore
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.errors import RecorderError
from sarmoco.processing.types import FloatArray

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
    segment : SegmentImage
        The store's image it holds.
    """

    xml: lxml.etree._ElementTree
    pixels: npt.NDArray[np.complex64]
    segment: SegmentImage


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


def _gps_datetime(t_ns: int, gps_minus_utc_s: int) -> datetime.datetime:
    unix_ns = gps_ns_to_unix_ns(t_ns, gps_minus_utc_s)
    epoch = datetime.datetime(1970, 1, 1, tzinfo=datetime.UTC)
    return epoch + datetime.timedelta(microseconds=unix_ns // 1000)


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


def _processing(cfg: Config, store: RunStore) -> list[dict[str, Any]]:
    """``ImageFormation/Processing``: the INS motion compensation and the autofocus."""
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
    segments = segment_images(store)
    if not 0 <= segment < len(segments):
        raise RecorderError(f"{store.path}: segment {segment} (the store has {len(segments)})")
    seg = segments[segment]
    return SicdProduct(_xml(store, cfg, geo, seg), _pixels(seg, cfg), seg)


def _pixels(seg: SegmentImage, cfg: Config) -> npt.NDArray[np.complex64]:
    out = seg.image.data.T
    if cfg.geometry.look_side == "left":
        out = out[:, ::-1]
    return np.ascontiguousarray(out, dtype=np.complex64)


def _xml(store: RunStore, cfg: Config, geo: Georeference, seg: SegmentImage) -> Any:
    radar = radar_params(cfg)
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

    i_scp = cols - 1 - scp_px[1] if left else scp_px[1]
    scp_ecf = geo.ecef(pixel(*scp_px))
    scp_llh = geo.geodetic(pixel(*scp_px))
    last = (rows - 1, cols - 1)
    corner_px = [(0, 0), (0, last[1]), last, (last[0], 0)]  # FRFC, FRLC, LRLC, LRFC
    corners = np.array([geo.geodetic(pixel(*rc))[:2] for rc in corner_px])

    t0_s = (seg.t0_ns - track.t0_ns) * 1e-9  # collect start on the track's clock
    duration = (seg.t1_ns - seg.t0_ns) * 1e-9
    x_scp = float(image.axis0_m[i_scp])
    arp0 = geo.ecef(track.origin_ned + track.x_hat * track.v0_mps * t0_s)
    arp_vel = geo.ecef_vector(track.x_hat * track.v0_mps)
    t_scp = x_scp / track.v0_mps - t0_s

    depth = cfg.geometry.height_m
    y_scp = float(image.axis1_m[scp_px[0]])
    cos_graze = y_scp / math.hypot(y_scp, depth)
    k_c = 2.0 * radar.carrier_hz / SPEED_OF_LIGHT_MPS
    row_bw = 2.0 * radar.bandwidth_hz / SPEED_OF_LIGHT_MPS * cos_graze
    beam = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    col_bw = 4.0 / radar.wavelength_m * math.sin(beam / 2.0)
    ss0, ss1 = image.spacing_m
    f_lo = radar.carrier_hz - radar.bandwidth_hz / 2.0
    f_hi = radar.carrier_hz + radar.bandwidth_hz / 2.0
    n_pulses = math.floor(duration * radar.prf_hz) + 1
    collect_s = n_pulses / radar.prf_hz  # the last pulse's interval ends after duration
    start = _gps_datetime(seg.t0_ns, cfg.ins.gps_minus_utc_s)

    root = lxml.etree.Element(f"{{{SICD_NS}}}SICD")
    sicd = sksicd.ElementWrapper(root)
    sicd["CollectionInfo"] = {
        "CollectorName": "sarmoco",
        "CoreName": f"{store.path.name}:segment{seg.tiles[0]}",
        "CollectType": "MONOSTATIC",
        "RadarMode": {"ModeType": "STRIPMAP"},
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
        "SCPPixel": np.array(scp_px),
    }
    sicd["GeoData"] = {
        "EarthModel": "WGS_84",
        "SCP": {"ECF": scp_ecf, "LLH": scp_llh},
        "ImageCorners": corners,
    }
    sicd["Grid"] = {
        "ImagePlane": "GROUND",
        "Type": "PLANE",
        "TimeCOAPoly": np.array([[t_scp, sign / track.v0_mps]]),
        "Row": _grid_dim(
            geo.ecef_vector(track.y_hat), ss1, row_bw, k_c * cos_graze, cfg.imaging.window
        ),
        "Col": _grid_dim(geo.ecef_vector(sign * track.x_hat), ss0, col_bw, 0.0, "none"),
    }
    sicd["Timeline"] = {
        "CollectStart": start,
        "CollectDuration": collect_s,
        "IPP": {
            "@size": 1,
            "Set": [
                {
                    "@index": 1,
                    "TStart": 0.0,
                    "TEnd": collect_s,
                    "IPPStart": 0,
                    "IPPEnd": n_pulses - 1,
                    "IPPPoly": np.array([0.0, radar.prf_hz]),
                }
            ],
        },
    }
    sicd["Position"] = {"ARPPoly": np.stack([arp0, arp_vel])}
    sicd["RadarCollection"] = {
        "TxFrequency": {"Min": f_lo, "Max": f_hi},
        "Waveform": {
            "@size": 1,
            "WFParameters": [
                {
                    "@index": 1,
                    "TxPulseLength": radar.pulse_width_s,
                    "TxRFBandwidth": radar.bandwidth_hz,
                    "TxFreqStart": f_lo,
                    "TxFMRate": radar.bandwidth_hz / radar.pulse_width_s,
                    "RcvDemodType": "CHIRP",
                    "ADCSampleRate": radar.sample_rate_hz,
                }
            ],
        },
        "TxPolarization": "UNKNOWN",
        "RcvChannels": {
            "@size": 1,
            "ChanParameters": [{"@index": 1, "TxRcvPolarization": "UNKNOWN"}],
        },
    }
    sicd["ImageFormation"] = {
        "RcvChanProc": {"NumChanProc": 1, "ChanIndex": [1]},
        "TxRcvPolarizationProc": "UNKNOWN",
        "TStartProc": 0.0,
        "TEndProc": duration,
        "TxFrequencyProc": {"MinProc": f_lo, "MaxProc": f_hi},
        "ImageFormAlgo": "OTHER",
        "STBeamComp": "NO",
        "ImageBeamComp": "NO",
        "AzAutofocus": "SV" if cfg.autofocus.enabled else "NO",
        "RgAutofocus": "NO",
        "Processing": _processing(cfg, store),
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
