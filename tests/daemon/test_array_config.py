"""The ``array`` configuration section: one channel per Tx/Rx pair, named errors."""

from __future__ import annotations

import pytest

from sarmoco.daemon.config import array_stream_ids, parse_config
from tests.daemon.refusals import assert_refused

ARRAY_RADAR = {"mode": "array", "channels": 160, "range_gate_delay_s": 1.0e-6}
"""An array-mode radar whose range window (149.9 .. 763.7 m: 4096 samples at 1 GHz after a
1 µs gate) holds the nadir range of a 200 m flight height."""


def _array_table(**array: object) -> dict[str, object]:
    return {
        "radar": dict(ARRAY_RADAR),
        "geometry": {"height_m": 200.0},
        "array": dict(array),
    }


def test_array_mode_takes_one_channel_per_pair() -> None:
    cfg = parse_config(_array_table())
    assert cfg.radar.mode == "array"
    assert cfg.radar.channels == cfg.array.n_tx * cfg.array.n_rx == 160
    assert cfg.array.sub_blocks == (1, 8)
    small = parse_config({**_array_table(n_tx=2, n_rx=8), "radar": ARRAY_RADAR | {"channels": 16}})
    assert small.array.n_rx == 8
    assert array_stream_ids(small) == tuple(range(16))  # unset: the pair numbers
    ids = [0x4000_0000 + 16 * c for c in range(16)]
    digitiser = parse_config(
        {**_array_table(n_tx=2, n_rx=8, stream_ids=ids), "radar": ARRAY_RADAR | {"channels": 16}}
    )
    assert array_stream_ids(digitiser) == tuple(ids)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"radar": {"channels": 160}}, "radar.channels: 160: single mode focuses one channel"),
        (
            {**_array_table(), "radar": ARRAY_RADAR | {"channels": 80}},
            "radar.channels: 80 is not array.n_tx * array.n_rx = 2 * 80 = 160",
        ),
        (_array_table(sub_blocks=[2, 0]), "array.sub_blocks[1]: 0 is not >= 1"),
        (_array_table(sub_blocks=[2]), "array.sub_blocks: [2] is not a list of 2 numbers"),
        (_array_table(n_rx=0), "array.n_rx: 0 is not > 0"),
        (
            {**_array_table(n_tx=1, n_rx=1), "radar": ARRAY_RADAR | {"channels": 1}},
            "array.n_rx: 1 * 1 Tx/Rx pairs make no virtual array (at least 2)",
        ),
        (
            {**_array_table(), "radar": ARRAY_RADAR | {"receive": "dechirp"}},
            "radar.receive: 'dechirp': the array imager needs 'matched'",
        ),
        (_array_table(max_look_deg=90), "array.max_look_deg: 90 is not < 90"),
        (
            {**_array_table(), "geometry": {"height_m": 100.0}},
            "geometry.height_m: 100.0 m (the nadir range) is outside the range window 149.90 ..",
        ),
        (_array_table(dem_spacing_m=-1), "array.dem_spacing_m: -1 is not > 0"),
        (_array_table(epc_spacing_m=0), "array.epc_spacing_m: 0 is not > 0"),
        ({"radar": {"mode": "mimo"}}, "radar.mode: 'mimo' is not one of 'single', 'array'"),
        (
            _array_table(stream_ids=[1, 2, 3]),
            "array.stream_ids: 3 stream IDs for array.n_tx * array.n_rx = 160 Tx/Rx pairs",
        ),
        (
            _array_table(stream_ids=[*range(159), 7]),
            "array.stream_ids: stream IDs 7 name more than one Tx/Rx pair",
        ),
        (_array_table(stream_ids=[-1]), "array.stream_ids[0]: -1 is not >= 0"),
        (_array_table(stream_ids=7), "array.stream_ids: 7 is not a list"),
    ],
    ids=[
        "single-many",
        "array-count",
        "sub-blocks-zero",
        "sub-blocks-len",
        "n-rx",
        "one-pair",
        "dechirp",
        "look",
        "nadir-outside",
        "spacing",
        "epc-spacing",
        "mode",
        "stream-ids-count",
        "stream-ids-twice",
        "stream-ids-negative",
        "stream-ids-not-a-list",
    ],
)
def test_bad_array_settings_name_the_key(table: dict[str, object], message: str) -> None:
    assert_refused(table, message)
