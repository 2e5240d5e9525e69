"""CRSD (NGA.STND.0080, version 1.0): a store's raw echoes as compensated received signal
data, written with sarkit.

A ``CRSDsar`` file holds one transmit sequence (the radar's pulses: times, antenna
positions, the chirp) and one receive channel (the echoes as the receiver sampled them,
at baseband about the carrier, with the antenna positions at the start of each receive
window). Unlike the CPHD (:mod:`sarmoco.products.cphd`), nothing is range compressed or
deramped: a CRSD reader forms its own phase history from the samples, the waveform and
the geometry.

What sarmoco does to the samples, and what it states:

* **A common sample clock.** CRSD asks every receive window of a channel to start a whole
  number of sample periods after the first. The recorded pulses start wherever the radar's
  time stamps put them (pulse repetition intervals need not be whole samples), so each
  pulse is delayed by the fraction of a sample (at most half) that puts its first sample on
  the clock of the first pulse (band-limited interpolation,
  :func:`sarmoco.processing.mocomp.shift_range`), and ``RcvStart`` is that grid time.
* **True baseband.** A receiver that delivers the conjugate baseband
  (``radar.iq_conjugate``) has its samples conjugated.
* **Geometry.** Transmit and receive antenna positions are the INS-integrated antenna
  track of the segment (:func:`sarmoco.products.cphd.segment_echoes`) in ECEF through the
  store's georeference, the receive position moved by the velocity to the receive
  window's start. The antenna frame is the along-track direction (X) and the direction
  toward the scene centre across it (boresight Z); the antenna pattern is not
  characterised (flat gain and phase, stated in the file), nor are the radiated power,
  the receiver gain and the noise (zero, stated).

Dechirped (FMCW) recordings are refused: their reference-chirp receive
(``DFIC0``/``FICRate``) is not written.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lxml.etree
import numpy as np
import numpy.typing as npt
import sarkit.crsd as skcrsd

from sarmoco import __version__
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.errors import RecorderError
from sarmoco.processing.mocomp import shift_range
from sarmoco.processing.types import FloatArray, IntArray, RadarParams
from sarmoco.products.cphd import IMAGE_AREA_HALF_M, gps_utc, scene_xml, segment_echoes
from sarmoco.store.reader import RunStore

CRSD_NS = "http://api.nsgreg.nga.mil/schema/crsd/1.0"
"""Namespace of the CRSD version written."""
TX_ID = "tx"
"""Identifier of the transmit sequence."""
CH_ID = "rx"
"""Identifier of the receive channel."""
_FLAT_GP = "flat_gain_phase"
"""Support array of the (uncharacterised) antenna pattern: 0 dB, 0 cycles everywhere."""
_FX_RESPONSE = "flat_fx_response"
"""Support array of the (uncharacterised) transmit frequency response: amplitude 1."""
_PPP_LAYOUT = (
    ("TxTime", "Int=I8;Frac=F8;"), ("TxPos", "X=F8;Y=F8;Z=F8;"), ("TxVel", "X=F8;Y=F8;Z=F8;"),
    ("FX1", "F8"), ("FX2", "F8"), ("TXmt", "F8"), ("PhiX0", "Int=I8;Frac=F8;"),
    ("FxFreq0", "F8"), ("FxRate", "F8"), ("TxRadInt", "F8"), ("TxACX", "X=F8;Y=F8;Z=F8;"),
    ("TxACY", "X=F8;Y=F8;Z=F8;"), ("TxEB", "DCX=F8;DCY=F8;"), ("FxResponseIndex", "I8"),
)  # fmt: skip
"""Per-pulse parameters written (name, CRSD binary format), in file order."""
_PVP_LAYOUT = (
    ("RcvStart", "Int=I8;Frac=F8;"), ("RcvPos", "X=F8;Y=F8;Z=F8;"),
    ("RcvVel", "X=F8;Y=F8;Z=F8;"), ("FRCV1", "F8"), ("FRCV2", "F8"),
    ("RefPhi0", "Int=I8;Frac=F8;"), ("RefFreq", "F8"), ("DFIC0", "F8"), ("FICRate", "F8"),
    ("RcvACX", "X=F8;Y=F8;Z=F8;"), ("RcvACY", "X=F8;Y=F8;Z=F8;"), ("RcvEB", "DCX=F8;DCY=F8;"),
    ("SIGNAL", "I8"), ("AmpSF", "F8"), ("DGRGC", "F8"), ("TxPulseIndex", "I8"),
)  # fmt: skip
"""Per-vector parameters written, in file order."""


@dataclass(frozen=True)
class ReceivedSignal:
    """One segment's echoes on a common sample clock, with the geometry of each pulse.

    Attributes
    ----------
    signal : ndarray of complex64, shape (V, N)
        Baseband samples about ``carrier_hz``; sample n of vector v was received at
        ``rcv_start_s[v] + n / sample_rate_hz``.
    radar : RadarParams
        The radar that recorded them.
    ref_ns : int
        The instant all times count from (``CollectionRefTime``), GPS ns; a whole UTC
        microsecond.
    ref_utc : datetime
        The same instant in UTC.
    tx_ns : ndarray of int64, shape (V,)
        Transmit time of each pulse (the recorded pulse time), GPS ns.
    rcv_start_s : ndarray of float64, shape (V,)
        Time of each vector's first sample from ``ref_ns``, s: on one sample clock.
    sub_sample_shift : ndarray of float64, shape (V,)
        Delay applied to each pulse to put it on that clock, samples (within ±0.5).
    apc_ecef_m : ndarray of float64, shape (V, 3)
        Antenna phase centre at transmit, ECEF, m.
    vel_ecef_mps : ndarray of float64, shape (V, 3)
        Its velocity, ECEF, m/s.
    srp_ecef_m : ndarray of float64, shape (3,)
        Scene centre point of the segment, ECEF, m.
    iarp_lla : tuple of 3 float
        The same point: latitude, longitude (deg), height (m).
    notes : tuple of (str, str)
        Provenance stated in the file.
    """

    signal: npt.NDArray[np.complex64]
    radar: RadarParams
    ref_ns: int
    ref_utc: datetime.datetime
    tx_ns: IntArray
    rcv_start_s: FloatArray
    sub_sample_shift: FloatArray
    apc_ecef_m: FloatArray
    vel_ecef_mps: FloatArray
    srp_ecef_m: FloatArray
    iarp_lla: tuple[float, float, float]
    notes: tuple[tuple[str, str], ...]

    def tx_s(self) -> FloatArray:
        """Transmit times from ``ref_ns``, s."""
        return np.asarray((self.tx_ns - self.ref_ns) * 1e-9)


def received_signal(store: RunStore, segment: int = 0) -> ReceivedSignal:
    """The raw echoes of one reference-track segment on one sample clock (module docstring).

    Raises
    ------
    RecorderError
        No absolute position, no raw echoes, no such segment, or dechirped echoes.
    """
    seg = segment_echoes(store, segment)
    radar = seg.config.radar.params()
    if radar.receive != "matched":
        raise RecorderError(
            f"{store.path}: radar.receive = {radar.receive!r}: CRSD export takes matched "
            "(pulsed chirp) echoes only"
        )
    fs, t = radar.sample_rate_hz, seg.t_ns
    gps_minus_utc = seg.config.ins.gps_minus_utc_s
    ref_ns = int(t[0]) - gps_ns_to_unix_ns(int(t[0]), gps_minus_utc) % 1000
    since_first = (t - t[0]) * (fs * 1e-9)
    whole = np.round(since_first)
    shift = since_first - whole
    echo = np.conj(seg.echo) if radar.iq_conjugate else seg.echo
    signal = shift_range(echo, shift).astype(np.complex64)
    rcv_start = (int(t[0]) - ref_ns) * 1e-9 + radar.range_gate_delay_s + whole / fs
    apc = seg.georef.ecef(seg.pos_m)
    srp = seg.georef.ecef(seg.srp_m)
    return ReceivedSignal(
        signal=signal,
        radar=radar,
        ref_ns=ref_ns,
        ref_utc=gps_utc(ref_ns, gps_minus_utc),
        tx_ns=t,
        rcv_start_s=rcv_start,
        sub_sample_shift=shift,
        apc_ecef_m=apc,
        vel_ecef_mps=np.gradient(apc, (t - t[0]) * 1e-9, axis=0),
        srp_ecef_m=srp,
        iarp_lla=tuple(float(v) for v in seg.georef.geodetic(seg.srp_m)),  # type: ignore[arg-type]
        notes=(
            ("source", f"{store.path.name}: segment {segment}, {t.size} pulses"),
            ("sample_clock", "each pulse delayed by under half a sample onto the first's"),
            ("antenna_pattern", "not characterised: flat gain and phase"),
            ("radiometry", "not calibrated: TxRadInt, PNCRSD and DGRGC are zero"),
            *seg.georef.parameters(),
        ),
    )


def _antenna_axes(rs: ReceivedSignal) -> tuple[FloatArray, FloatArray]:
    """Antenna frame X (along track) and Y (``Z x X``, Z toward the scene centre across the
    track) of each pulse, ECEF unit vectors."""
    x = rs.vel_ecef_mps / np.linalg.norm(rs.vel_ecef_mps, axis=1, keepdims=True)
    look = rs.srp_ecef_m - rs.apc_ecef_m
    z = look - np.sum(look * x, axis=1, keepdims=True) * x
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    return x, np.cross(z, x)


def _pxp_dtype(layout: tuple[tuple[str, str], ...]) -> np.dtype[Any]:
    """The numpy dtype of a per-pulse or per-vector record: the fields packed in order."""
    return np.dtype([(name, skcrsd.binary_format_string_to_dtype(fmt)) for name, fmt in layout])


def _pxp_xml(layout: tuple[tuple[str, str], ...]) -> dict[str, Any]:
    """The ``PPP``/``PVP`` XML of a layout: offset and size of each field in 8-byte words."""
    out, offset = {}, 0
    for name, fmt in layout:
        dtype = skcrsd.binary_format_string_to_dtype(fmt)
        out[name] = {"Offset": offset, "Size": dtype.itemsize // 8, "dtype": dtype}
        offset += dtype.itemsize // 8
    return out


def _int_frac(seconds: FloatArray) -> npt.NDArray[Any]:
    out = np.zeros(seconds.shape, dtype=skcrsd.binary_format_string_to_dtype("Int=I8;Frac=F8;"))
    out["Int"] = np.floor(seconds)
    out["Frac"] = seconds - out["Int"]
    return out


def _ppps(rs: ReceivedSignal) -> npt.NDArray[Any]:
    radar = rs.radar
    k = radar.bandwidth_hz / radar.pulse_width_s * (1.0 if radar.chirp_direction == "up" else -1.0)
    acx, acy = _antenna_axes(rs)
    ppp = np.zeros(rs.tx_ns.size, dtype=_pxp_dtype(_PPP_LAYOUT))
    ppp["TxTime"] = _int_frac(rs.tx_s())
    ppp["TxPos"] = rs.apc_ecef_m
    ppp["TxVel"] = rs.vel_ecef_mps
    ppp["FX1"] = radar.carrier_hz - radar.bandwidth_hz / 2.0
    ppp["FX2"] = radar.carrier_hz + radar.bandwidth_hz / 2.0
    ppp["TXmt"] = radar.pulse_width_s
    ppp["FxFreq0"] = radar.carrier_hz - k * radar.pulse_width_s / 2.0
    ppp["FxRate"] = k
    ppp["TxACX"], ppp["TxACY"] = acx, acy
    return ppp


def _pvps(rs: ReceivedSignal) -> npt.NDArray[Any]:
    radar = rs.radar
    acx, acy = _antenna_axes(rs)
    late = rs.rcv_start_s - rs.tx_s()
    pvp = np.zeros(rs.tx_ns.size, dtype=_pxp_dtype(_PVP_LAYOUT))
    pvp["RcvStart"] = _int_frac(rs.rcv_start_s)
    pvp["RcvPos"] = rs.apc_ecef_m + rs.vel_ecef_mps * late[:, None]
    pvp["RcvVel"] = rs.vel_ecef_mps
    pvp["FRCV1"] = radar.carrier_hz - radar.bandwidth_hz / 2.0
    pvp["FRCV2"] = radar.carrier_hz + radar.bandwidth_hz / 2.0
    pvp["RefFreq"] = radar.carrier_hz
    pvp["RcvACX"], pvp["RcvACY"] = acx, acy
    pvp["SIGNAL"] = 1
    pvp["AmpSF"] = 1.0
    pvp["TxPulseIndex"] = np.arange(rs.tx_ns.size)
    return pvp


def _polarization(
    pos: FloatArray, acx: FloatArray, acy: FloatArray, ref: FloatArray, sign: int
) -> dict[str, Any]:
    """H/V description of an antenna polarized along its Y axis (``AntPolRef`` AmpY = 1),
    seen from ``pos`` toward ``ref``; named V (the Y axis lies in the plane of the look and
    the vertical)."""
    amp_h, amp_v, ph_h, ph_v = skcrsd.compute_h_v_pol_parameters(
        pos, acx, acy, ref, sign, 0.0, 1.0, 0.0, 0.0
    )
    return {"PolarizationID": "V", "AmpH": amp_h, "AmpV": amp_v, "PhaseH": ph_h, "PhaseV": ph_v}


def _image_area() -> dict[str, Any]:
    """The square image area about the IARP (:data:`~sarmoco.products.cphd.IMAGE_AREA_HALF_M`),
    its polygon clockwise."""
    h = IMAGE_AREA_HALF_M
    return {"X1Y1": [-h, -h], "X2Y2": [h, h], "Polygon": [[-h, -h], [-h, h], [h, h], [h, -h]]}


def _info_xml(crsd: Any, rs: ReceivedSignal, core_name: str) -> None:
    crsd["ProductInfo"] = {
        "ProductName": core_name,
        "Classification": "UNCLASSIFIED",
        "ReleaseInfo": "UNRESTRICTED",
        "CreationInfo": [
            {
                "Application": f"sarmoco {__version__}",
                "DateTime": datetime.datetime.now(datetime.UTC),
            }
        ],
        "Parameter": list(rs.notes),
    }
    crsd["SARInfo"] = {"CollectType": "MONOSTATIC", "RadarMode": {"ModeType": "STRIPMAP"}}
    crsd["TransmitInfo"] = {"SensorName": "sarmoco", "EventName": core_name}
    crsd["ReceiveInfo"] = {"SensorName": "sarmoco", "EventName": core_name}


def _data_xml(rs: ReceivedSignal) -> dict[str, Any]:
    v, n = rs.signal.shape
    return {
        "Support": {
            "NumSupportArrays": 2,
            "SupportArray": [
                {
                    "SAId": _FLAT_GP,
                    "NumRows": 3,
                    "NumCols": 3,
                    "BytesPerElement": 8,
                    "ArrayByteOffset": 0,
                },
                {
                    "SAId": _FX_RESPONSE,
                    "NumRows": 1,
                    "NumCols": 3,
                    "BytesPerElement": 8,
                    "ArrayByteOffset": 72,
                },
            ],
        },
        "Transmit": {
            "NumBytesPPP": _pxp_dtype(_PPP_LAYOUT).itemsize,
            "NumTxSequences": 1,
            "TxSequence": [{"TxId": TX_ID, "NumPulses": v, "PPPArrayByteOffset": 0}],
        },
        "Receive": {
            "SignalArrayFormat": "CF8",
            "NumBytesPVP": _pxp_dtype(_PVP_LAYOUT).itemsize,
            "NumCRSDChannels": 1,
            "Channel": [
                {
                    "ChId": CH_ID,
                    "NumVectors": v,
                    "NumSamples": n,
                    "SignalArrayByteOffset": 0,
                    "PVPArrayByteOffset": 0,
                },
            ],
        },
    }


def _sequences_xml(
    crsd: Any, rs: ReceivedSignal, ppp: npt.NDArray[Any], pvp: npt.NDArray[Any]
) -> None:
    radar = rs.radar
    ref = rs.tx_ns.size // 2
    tx_s, srp = rs.tx_s(), rs.srp_ecef_m
    fx1, fx2 = float(ppp["FX1"][0]), float(ppp["FX2"][0])
    point = {"ECF": srp, "IAC": [0.0, 0.0]}
    tx_pol = _polarization(ppp["TxPos"][ref], ppp["TxACX"][ref], ppp["TxACY"][ref], srp, 1)
    crsd["TxSequence"] = {
        "RefTxId": TX_ID,
        "TxWFType": "LFM",
        "Parameters": [{
            "Identifier": TX_ID, "RefPulseIndex": ref, "FxResponseId": _FX_RESPONSE,
            "FxBWFixed": True, "FxC": (fx1 + fx2) / 2.0, "FxBW": fx2 - fx1,
            "TXmtMin": radar.pulse_width_s, "TXmtMax": radar.pulse_width_s,
            "TxTime1": float(tx_s[0]), "TxTime2": float(tx_s[-1]), "TxAPCId": "apc",
            "TxAPATId": "pattern", "TxRefPoint": point, "TxPolarization": tx_pol,
            "TxRefRadIntensity": 0.0, "TxRadIntErrorStdDev": 0.0, "TxRefLAtm": 1.0,
        }],
    }  # fmt: skip
    crsd["Channel"] = {
        "RefChId": CH_ID,
        "Parameters": [{
            "Identifier": CH_ID, "RefVectorIndex": ref, "RefFreqFixed": True,
            "FrcvFixed": True, "SignalNormal": True, "F0Ref": radar.carrier_hz,
            "Fs": radar.sample_rate_hz, "BWInst": radar.bandwidth_hz,
            "RcvStartTime1": float(rs.rcv_start_s[0]),
            "RcvStartTime2": float(rs.rcv_start_s[-1]),
            "FrcvMin": float(pvp["FRCV1"][0]), "FrcvMax": float(pvp["FRCV2"][0]),
            "RcvAPCId": "apc", "RcvAPATId": "pattern", "RcvRefPoint": point,
            "RcvPolarization": _polarization(
                pvp["RcvPos"][ref], pvp["RcvACX"][ref], pvp["RcvACY"][ref], srp, -1
            ),
            "RcvRefIrradiance": 0.0, "RcvIrradianceErrorStdDev": 0.0, "RcvRefLAtm": 1.0,
            "PNCRSD": 0.0, "BNCRSD": 1.0,
            "SARImage": {
                "TxId": TX_ID, "RefVectorPulseIndex": ref, "TxPolarization": tx_pol,
                "DwellTimes": {"Polynomials": {"CODId": "cod", "DwellId": "dwell"}},
                "ImageArea": _image_area(),
            },
        }],
    }  # fmt: skip


def _support_xml(crsd: Any, rs: ReceivedSignal, fx1: float, fx2: float) -> None:
    tx_s = rs.tx_s()
    crsd["DwellPolynomials"] = {
        "NumCODTimes": 1,
        "CODTime": [{"Identifier": "cod", "CODTimePoly": [[(tx_s[0] + tx_s[-1]) / 2.0]]}],
        "NumDwellTimes": 1,
        "DwellTime": [{"Identifier": "dwell", "DwellTimePoly": [[tx_s[-1] - tx_s[0]]]}],
    }
    crsd["SupportArray"] = {
        "GainPhaseArray": [{
            "Identifier": _FLAT_GP, "ElementFormat": "Gain=F4;Phase=F4;",
            "X0": -1.0, "Y0": -1.0, "XSS": 1.0, "YSS": 1.0,
        }],
        "FxResponseArray": [{
            "Identifier": _FX_RESPONSE, "ElementFormat": "Amp=F4;Phase=F4;",
            "Fx0FXR": fx1, "FxSSFXR": (fx2 - fx1) / 2.0,
        }],
    }  # fmt: skip
    crsd["PPP"] = _pxp_xml(_PPP_LAYOUT)
    crsd["PVP"] = _pxp_xml(_PVP_LAYOUT)
    pattern = {"DCXSF": 0.0, "DCYSF": 0.0}
    crsd["Antenna"] = {
        "NumACFs": 1, "NumAPCs": 1, "NumAPATs": 1,
        "AntCoordFrame": [{"Identifier": "acf"}],
        "AntPhaseCenter": [{"Identifier": "apc", "ACFId": "acf", "APCXYZ": [0.0, 0.0, 0.0]}],
        "AntPattern": [{
            "Identifier": "pattern", "FreqZero": (fx1 + fx2) / 2.0, "ArrayGPId": _FLAT_GP,
            "ElemGPId": _FLAT_GP, "EBFreqShift": pattern, "MLFreqDilation": pattern,
            "GainBSPoly": [0.0],
            "AntPolRef": {"AmpX": 0.0, "AmpY": 1.0, "PhaseX": 0.0, "PhaseY": 0.0},
        }],
    }  # fmt: skip


def crsd_xml(
    rs: ReceivedSignal, ppp: npt.NDArray[Any], pvp: npt.NDArray[Any], core_name: str
) -> lxml.etree._ElementTree:
    """The CRSDsar XML of a received signal, its reference geometry computed by sarkit."""
    root = lxml.etree.Element(f"{{{CRSD_NS}}}CRSDsar")
    crsd = skcrsd.ElementWrapper(root)
    _info_xml(crsd, rs, core_name)
    fx1, fx2 = float(ppp["FX1"][0]), float(ppp["FX2"][0])
    crsd["Global"] = {
        "CollectionRefTime": rs.ref_utc,
        "Transmit": {"TxTime1": float(rs.tx_s()[0]), "TxTime2": float(rs.tx_s()[-1]),
                     "FxMin": fx1, "FxMax": fx2},
        "Receive": {"RcvStartTime1": float(rs.rcv_start_s[0]),
                    "RcvStartTime2": float(rs.rcv_start_s[-1]),
                    "FrcvMin": float(pvp["FRCV1"][0]), "FrcvMax": float(pvp["FRCV2"][0])},
    }  # fmt: skip
    scene = scene_xml(rs.iarp_lla)
    scene["ImageArea"] = _image_area()
    crsd["SceneCoordinates"] = scene
    crsd["Data"] = _data_xml(rs)
    _sequences_xml(crsd, rs, ppp, pvp)
    _support_xml(crsd, rs, fx1, fx2)
    tree = root.getroottree()
    geometry = skcrsd.compute_reference_geometry(tree, pvps=pvp, ppps=ppp)
    root.insert(root.index(root.find("{*}Channel")) + 1, geometry)
    return tree


def write_crsd(store: RunStore, path: Path, segment: int = 0) -> ReceivedSignal:
    """Write one reference-track segment's echoes as CRSD 1.0 (``CRSDsar``); return what
    was written."""
    rs = received_signal(store, segment)
    ppp, pvp = _ppps(rs), _pvps(rs)
    tree = crsd_xml(rs, ppp, pvp, f"{store.path.name} segment {segment}")
    gain_phase = np.zeros((3, 3), dtype=[("Gain", ">f4"), ("Phase", ">f4")])
    response = np.zeros((1, 3), dtype=[("Amp", ">f4"), ("Phase", ">f4")])
    response["Amp"] = 1.0
    with path.open("wb") as f, skcrsd.Writer(f, skcrsd.Metadata(xmltree=tree)) as writer:
        writer.write_support_array(_FLAT_GP, gain_phase)
        writer.write_support_array(_FX_RESPONSE, response)
        writer.write_ppp(TX_ID, ppp)
        writer.write_pvp(CH_ID, pvp)
        writer.write_signal(CH_ID, rs.signal)
    return rs
