"""One receive channel: the daemon's radar link keeps VITA stream 0 and counts and skips the
packets of every other stream, so a second channel is never mixed into the aperture.

Two streams are interleaved on a real UDP socket and in a ``.vrt`` file, read by the link the
configuration opens (:func:`~sarmoco.daemon.links.open_radar`) into a pipeline's ring.
"""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np

from sarmoco.daemon.config import Config, parse_config
from sarmoco.daemon.links import open_radar
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
from sarmoco.drivers.radar import RadarSource
from sarmoco.drivers.vita49 import encode_context_packet, encode_signal_packet

N_SAMPLES = 64
N_PER_STREAM = 100
"""Pulses per stream: more than a decode batch (the UDP path's vectorised decode)."""
T0_NS = 1_400_000_000 * 10**9
PRI_NS = 10**7
OTHER_STREAM = 1


def _config(link: str) -> Config:
    return parse_config(
        {
            "radar": {"link": link, "n_samples": N_SAMPLES, "prf_hz": 100.0},
            # a scene inside the short range window (749.5 .. 759 m)
            "geometry": {"center_slant_range_m": 754.0},
            "imaging": {"swath_m": 4.0},
            "status": {"http_port": 0},
        }
    )


def _packets() -> list[bytes]:
    """Stream 0 and stream 1 pulses interleaved (stream 1's carry negative values), with
    a context packet of each stream first."""
    out = [
        encode_context_packet(
            sid, T0_NS, 0, bandwidth_hz=750e6, rf_reference_hz=15e9, sample_rate_hz=1e9
        )
        for sid in (0, OTHER_STREAM)
    ]
    for k in range(N_PER_STREAM):
        for sid, sign in ((0, 1), (OTHER_STREAM, -1)):
            iq = np.full((N_SAMPLES, 2), sign * (k + 1), np.int16)
            out.append(encode_signal_packet(sid, T0_NS + k * PRI_NS, k % 16, iq))
    return out


def _read_all(pipe: Pipeline, src: RadarSource) -> int:
    got = 0
    while got < N_PER_STREAM and (more := pipe.read_radar(src, 1.0)):
        got += more
    return got


def _check(pipe: Pipeline, src: RadarSource) -> None:
    assert len(pipe.ring) == N_PER_STREAM
    batch = pipe.ring.pop(N_PER_STREAM)
    np.testing.assert_array_equal(batch.t_ns, T0_NS + np.arange(N_PER_STREAM) * PRI_NS)
    np.testing.assert_array_equal(batch.channel, 0)
    np.testing.assert_array_equal(batch.complex_samples()[:, 0].real, np.arange(1, 101))
    assert not batch.flags.any()  # no pulse looks lost: each stream's count runs on its own
    counters = src.decoder.counters
    assert counters.rejected == N_PER_STREAM
    assert counters.frames == N_PER_STREAM + 2  # stream 0's pulses and both context packets
    assert counters.gaps == 0 and counters.parse_errors == 0 and counters.skipped_bytes == 0
    assert src.decoder.skipped_streams == {OTHER_STREAM}


def test_udp_link_keeps_stream_zero(tmp_path: Path) -> None:
    cfg = _config("udp://127.0.0.1:0")
    with open_recorder(cfg, tmp_path / "udp.zarr") as rec, open_radar(cfg) as src:
        pipe = Pipeline(cfg, rec, Counters())
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for p in _packets():
                tx.sendto(p, src.address)  # type: ignore[attr-defined]
        assert _read_all(pipe, src) == N_PER_STREAM
        _check(pipe, src)


def test_vrt_file_keeps_stream_zero(tmp_path: Path) -> None:
    path = tmp_path / "two-streams.vrt"
    path.write_bytes(b"".join(_packets()))
    cfg = _config(str(path))
    with open_recorder(cfg, tmp_path / "vrt.zarr") as rec, open_radar(cfg) as src:
        pipe = Pipeline(cfg, rec, Counters())
        assert _read_all(pipe, src) == N_PER_STREAM
        assert pipe.read_radar(src, 0.0) == 0 and src.eof
        _check(pipe, src)
