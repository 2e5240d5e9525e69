"""Coverage-guided fuzzing harness (atheris/libFuzzer) for the decoders; run by the
``fuzz_long`` tests as ``python -m tests.fuzz.atheris_harness TARGET -runs=N ...``.

Each target feeds the fuzzer's bytes to one decoder and lets only what the decoder may
raise by contract pass; anything else propagates, and libFuzzer reports it as a crash
(with the input saved). libFuzzer's ``-rss_limit_mb`` bounds the memory of the run.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import atheris

with atheris.instrument_imports():
    import numpy as np

    from sarmoco.daemon.config import load_config
    from sarmoco.drivers import sbg_can
    from sarmoco.drivers.sbg import SbgDecoder
    from sarmoco.drivers.vita49 import VitaDecoder, VitaStreamFramer
    from sarmoco.errors import ConfigError


def vita(data: bytes) -> None:
    """One datagram, then the same bytes as a stream through the framer."""
    dec = VitaDecoder(16)
    row = np.empty(16, np.complex64)
    dec.decode_into(data, row)
    framer = VitaStreamFramer(dec)
    framer.feed(data)
    while (pkt := framer.next_packet()) is not None:
        dec.decode_into(pkt, row)
        framer.consume(pkt, dec.last_ok)


def sbg(data: bytes) -> None:
    """sbgECom bytes (to the end of a file), then the same bytes cut into CAN frames."""
    SbgDecoder().feed(data, final=True)
    can = sbg_can.SbgCanDecoder()
    for i in range(0, len(data) - 2, 10):
        can.feed(0x100 + data[i] % 0x110, data[i + 2 : i + 2 + data[i + 1] % 12])


_TMP_DIR = tempfile.TemporaryDirectory(prefix="sarmoco-atheris-")  # removed at exit
_TMP = Path(_TMP_DIR.name)


def config(data: bytes) -> None:
    """Bytes as a configuration file: a Config or a ConfigError, nothing else."""
    path = _TMP / "sarmoco.toml"
    path.write_bytes(data)
    try:
        load_config(path)
    except ConfigError:
        pass


TARGETS: dict[str, Callable[[bytes], None]] = {"vita": vita, "sbg": sbg, "config": config}

if __name__ == "__main__":
    target = TARGETS[sys.argv[1]]
    atheris.Setup([sys.argv[0], *sys.argv[2:]], target)
    atheris.Fuzz()
