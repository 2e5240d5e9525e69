"""Georeferencing parts: WGS-84 conversions, the store's geodetic codecs and the
SBG decoder's positions.

The conversions are checked against sarkit's independent WGS-84 implementation; the
codecs through a real store on disk; the decoder on sbgECom frames it decodes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from sarkit import wgs84

from sarmoco.daemon.navframe import StoreFrame
from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.samples import AttitudeSample, TangentFrame, Validity, VelocitySample
from sarmoco.drivers.sbg import SbgDecoder
from sarmoco.errors import RecorderError
from sarmoco.geodesy import (
    ecef_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_ned,
    ned_rotation,
    ned_to_ecef,
    ned_to_geodetic,
)
from sarmoco.store import schema
from sarmoco.store.flags import PushResult
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder
from tests.drivers.test_sbg import LEAP, OK_STATUS, utc_msg

POINTS = np.array(
    [[47.3769, 8.5417, 408.0], [-33.9, 151.2, -30.0], [89.9, -120.0, 1.0e4], [0.0, 0.0, 0.0]]
)


def test_geodetic_and_ecef_agree_with_sarkit() -> None:
    xyz = geodetic_to_ecef(POINTS)
    assert np.allclose(xyz, wgs84.geodetic_to_cartesian(POINTS), atol=1e-6)
    back = ecef_to_geodetic(xyz)
    assert np.allclose(back[:, :2], POINTS[:, :2], atol=1e-11)
    assert np.allclose(back[:, 2], POINTS[:, 2], atol=1e-6)
    assert np.allclose(ecef_to_geodetic(wgs84.geodetic_to_cartesian(POINTS)), back, atol=1e-6)


def test_ned_axes_and_round_trip() -> None:
    origin = (47.3769, 8.5417, 408.0)
    rot = ned_rotation(origin[0], origin[1])
    assert np.allclose(rot @ rot.T, np.eye(3), atol=1e-15)
    assert np.allclose(-rot[2], wgs84.up(np.asarray(origin)), atol=1e-12)  # down is -up
    ned = np.array([[100.0, -250.0, -80.0], [0.0, 0.0, 0.0], [3.0, 900.0, 100.0]])
    assert np.allclose(geodetic_to_ned(ecef_to_geodetic(ned_to_ecef(ned, origin)), origin), ned)
    # 1 km north is about 1/111.2 deg of latitude and leaves the longitude alone
    north = ecef_to_geodetic(ned_to_ecef(np.array([1000.0, 0.0, 0.0]), origin))
    assert north[0] - origin[0] == pytest.approx(1000.0 / 111_190.0, rel=2e-3)
    assert north[1] == pytest.approx(origin[1], abs=1e-9)


def test_ned_to_geodetic_is_exact_far_from_the_tangent_point() -> None:
    """900 m east of a point at 47° N (a scene's range from the track): back through
    geodetic_to_ned to 1 µm; the point lies 6.4 cm above the ellipsoid, and a flat-Earth
    mapping (latitude from north only) would put it 6.8 cm north of where it is."""
    origin = (47.3769, 8.5417, 408.0)
    ned = np.array([[0.0, 900.0, 0.0], [-1500.0, 2500.0, 120.0]])
    lla = ned_to_geodetic(ned, origin)
    assert np.allclose(geodetic_to_ned(lla, origin), ned, atol=1e-6)
    assert lla[0, 2] - origin[2] == pytest.approx(900.0**2 / (2 * 6_378_000.0), rel=0.01)
    assert lla[0, 0] < origin[0] - 0.06 / 111_190.0


def _rows() -> list[schema.NavRow]:
    lla = (47.0, 8.0, 500.0)
    return [
        (AttitudeSample(10, (1.0, 0.0, 0.0, 0.0), Validity.ATTITUDE, "x", 10), None,
         PushResult.ACCEPTED),
        (VelocitySample(20, (1.0, 2.0, 3.0), Validity.VELOCITY | Validity.POSITION, "x", 20,
                        lat_lon_alt=lla), 5, PushResult.DUPLICATE),
        (VelocitySample(30, (1.0, 2.0, 3.0), Validity.VELOCITY, "x", 30, lat_lon_alt=lla),
         6, PushResult.ACCEPTED),
        (VelocitySample(40, (1.0, 2.0, 3.0), Validity.VELOCITY | Validity.POSITION, "sbg", 40,
                        (1.0, 2.0, 3.0), lat_lon_alt=(47.5, 8.5, 510.0),
                        pos_frame=TangentFrame((47.4, 8.4, 500.0), "sbg")), 7,
         PushResult.ACCEPTED),
    ]  # fmt: skip


def test_the_nav_table_keeps_valid_positions_and_the_origin_is_the_first_accepted(
    tmp_path: Path,
) -> None:
    rows = _rows()
    path = tmp_path / "s.zarr"
    with Recorder(path, n_samples=4) as rec:
        rec.append_nav(**schema.encode_nav(rows))
        origin = schema.first_geodetic_origin(rows)
        rec.set_attribute(schema.GEODETIC_ORIGIN_ATTR, schema.encode_geodetic_origin(origin))
    store = open_store(path)
    cols = store.read("nav")
    # the DUPLICATE row's position is not an origin; a position without POSITION is not kept
    assert np.isnan(cols["lla"][[0, 2]]).all() and cols["lla"][1].tolist() == [47.0, 8.0, 500.0]
    decoded = schema.decode_nav(cols)
    assert isinstance(decoded[3], VelocitySample) and decoded[3].lat_lon_alt == (47.5, 8.5, 510.0)
    assert decoded[3].valid & Validity.POSITION and decoded[2].lat_lon_alt is None
    got = schema.decode_geodetic_origin(store.attrs, "s")
    assert got == schema.GeodeticOrigin(40, (47.4, 8.4, 500.0), "sbg")  # its position's frame
    assert store.attrs[schema.GEODETIC_ORIGIN_ATTR]["frame"] == schema.FRAME_STATED


def test_a_store_without_position_says_so(tmp_path: Path) -> None:
    path = tmp_path / "s.zarr"
    Recorder(path, n_samples=4).close()
    attrs = open_store(path).attrs
    assert attrs[schema.GEODETIC_ORIGIN_ATTR] == {
        "absent": schema.NO_ABSOLUTE_POSITION,
        "frame": schema.FRAME_UNSTATED,
    }
    with pytest.raises(RecorderError, match=r"s\.geodetic_origin: no absolute position"):
        schema.decode_geodetic_origin(attrs, "s")


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"lat_deg": 95.0, "lon_deg": 8.0, "alt_m": 0.0, "t_ns": 1, "source": "x"},
         r"x\.geodetic_origin: lat 95\.0"),
        ({"lat_deg": 45.0, "lon_deg": 8.0, "alt_m": 0.0, "source": "x"},
         r"x\.geodetic_origin\.t_ns: attribute missing"),
        ({"lat_deg": "45", "lon_deg": 8.0, "alt_m": 0.0, "t_ns": 1, "source": "x"},
         r"x\.geodetic_origin\.lat_deg: '45' is not a float or int"),
        ({"lat_deg": 45.0, "lon_deg": 8.0, "alt_m": math.nan, "t_ns": 1, "source": "x"},
         r"alt nan out of range"),
    ],
)  # fmt: skip
def test_a_damaged_origin_is_refused_naming_the_field(value: dict, message: str) -> None:
    with pytest.raises(RecorderError, match=message):
        schema.decode_geodetic_origin({schema.GEODETIC_ORIGIN_ATTR: value}, "x")


def test_sbg_positions_are_ned_about_the_first_valid_fix() -> None:
    """EKF_NAV gives the altitude above mean sea level and the geoid undulation: the
    positions are heights above the ellipsoid (their sum), NED about the first valid fix."""
    dec = SbgDecoder(LEAP)
    d1 = 100_000_000
    undulation = 47.4
    origin = (47.3769, 8.5417, 408.0)  # height above the ellipsoid
    moved = ecef_to_geodetic(ned_to_ecef(np.array([12.0, -3.0, -5.0]), origin))
    msl = [(lat, lon, h - undulation) for lat, lon, h in (origin, moved.tolist())]
    no_fix = codec.EkfNav(d1, (1.0, 0, 0), (0,) * 3, (10.0, 20.0, 30.0), 0.0, (0,) * 3, OK_STATUS)
    valid = OK_STATUS | codec.SOL_POSITION_VALID
    first = codec.EkfNav(d1 + 10_000, (1.0, 0, 0), (0,) * 3, msl[0], undulation, (0,) * 3, valid)
    second = codec.EkfNav(d1 + 20_000, (1.0, 0, 0), (0,) * 3, msl[1], undulation, (0,) * 3, valid)
    frames: list[codec.Message] = [utc_msg(d1 - 300_000), utc_msg(d1 - 100_000)]
    frames += [no_fix, first, second]
    out = dec.feed(b"".join(codec.encode_message(m) for m in frames))
    vel = [s for s in out if isinstance(s, VelocitySample)]
    assert len(vel) == 3
    assert vel[0].pos_ned is None and vel[0].lat_lon_alt is None  # position not valid
    assert vel[1].pos_ned == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert vel[2].pos_ned == pytest.approx((12.0, -3.0, -5.0), abs=1e-4)  # float32 undulation
    fix = vel[1].lat_lon_alt
    assert fix is not None and fix == pytest.approx(origin, abs=1e-4)
    assert dec.positions.frame == TangentFrame(fix, "sbg.EKF_NAV", ellipsoid_height=True)
    assert vel[1].pos_frame == vel[2].pos_frame == dec.positions.frame


def test_a_store_keeps_its_positions_in_the_first_frame_named() -> None:
    """Positions named in a later frame (an EKF origin stated after the first fixes) are
    re-expressed in the store's, to 1 µm; positions that name no frame pass unchanged."""
    first = TangentFrame((47.3769, 8.5417, 408.0), "mavlink.GLOBAL_POSITION_INT")
    ekf = TangentFrame((47.3700, 8.5500, 400.0), "mavlink.GPS_GLOBAL_ORIGIN", stated=True)
    point = np.array([47.3800, 8.5450, 510.0])
    frame = StoreFrame()

    def sample(t: int, where: TangentFrame | None) -> VelocitySample:
        pos = None if where is None else geodetic_to_ned(point, where.lat_lon_alt).tolist()
        return VelocitySample(t, (1.0, 0.0, 0.0), Validity.VELOCITY, "x", t, pos, pos_frame=where)

    assert frame.express(sample(0, None)).pos_ned is None and frame.frame is None
    a = frame.express(sample(1, first))
    b = frame.express(sample(2, ekf))
    assert frame.frame == first and a.pos_frame == b.pos_frame == first
    assert a.pos_ned is not None and b.pos_ned is not None
    assert np.allclose(b.pos_ned, a.pos_ned, atol=1e-6)
    assert np.linalg.norm(geodetic_to_ned(point, ekf.lat_lon_alt) - a.pos_ned) > 100.0
