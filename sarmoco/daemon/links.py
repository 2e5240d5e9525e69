"""Open the configured radar and INS links (live or from files) as driver sources.

INS protocols are a registry, :data:`INS_OPENERS`: protocol name (a value of
``ins.protocol``, :data:`sarmoco.daemon.config.InsProtocol`) to the function that opens
``ins.link`` with that protocol. Each opener imports its driver
when called (as python-can loads its interfaces), so the configuration, which needs
only the names, does not load pymavlink or python-can. A new protocol is one opener
here and its emitter in the simulator (``INS_EMITTERS``, which the tests hold to these names).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlsplit

from sarmoco.daemon.config import Config, InsConfig
from sarmoco.drivers.radar import RadarFileSource, RadarSource, RadarTcpSource, RadarUdpSource
from sarmoco.drivers.source import Source
from sarmoco.drivers.vita49 import ContextExpectation, VitaDecoder
from sarmoco.errors import ConfigError

CAN_LOG_SUFFIXES = (".log", ".asc", ".blf", ".trc", ".csv")
"""File suffixes that name a CAN log (replayed through ``can.LogReader``)."""


def vita_decoder(cfg: Config) -> VitaDecoder:
    """A VITA 49.2 decoder for the configured radar (context packets checked against it)."""
    r = cfg.radar
    return VitaDecoder(
        r.n_samples,
        r.sample_format,
        leap_s=cfg.ins.gps_minus_utc_s,
        expect=ContextExpectation.for_receiver(
            r.receive, r.bandwidth_hz, r.carrier_hz, r.sample_rate_hz
        ),
        link=r.link,
        # single mode: radar.stream_id, or the first signal stream seen; array mode: every
        # stream (the pulses are grouped by channel, sarmoco.daemon.channelgroup)
        stream_id=None if r.mode == "array" else r.stream_id,
        first_stream=r.mode != "array",
    )


def open_radar(
    cfg: Config, link: str | None = None, decoder: VitaDecoder | None = None
) -> RadarSource:
    """Open ``radar.link`` (or ``link``): ``udp://HOST:PORT``, ``tcp://HOST:PORT`` or a file.

    ``decoder``: the decoder of the link reopened (its counters, packet counts and context
    state go on across the reconnection); None: a new one (:func:`vita_decoder`).

    Raises
    ------
    ConfigError
        If the link is neither a known URL nor an existing file.
    DriverError
        If the socket or file cannot be opened.
    """
    text = cfg.radar.link if link is None else link
    decoder = vita_decoder(cfg) if decoder is None else decoder
    url = urlsplit(text)
    if url.scheme in ("udp", "tcp"):
        if url.hostname is None or url.port is None:
            raise ConfigError(f"radar.link: {text!r} lacks HOST:PORT")
        if url.scheme == "udp":
            return RadarUdpSource(url.hostname, url.port, decoder)
        return RadarTcpSource(url.hostname, url.port, decoder)
    if url.scheme in ("", "file") and Path(url.path).is_file():
        return RadarFileSource(url.path, decoder)
    raise ConfigError(
        f"radar.link: {text!r} is not udp://HOST:PORT, tcp://HOST:PORT or an existing file"
    )


def open_ins(cfg: Config, link: str | None = None, keep_raw: bool = False) -> Source:
    """Open ``ins.link`` (or ``link``) with the configured protocol.

    MAVLink: any pymavlink connection string, a ``.tlog`` or a dataflash ``.bin``.
    SBG: a serial device (a pseudo-terminal in simulation) or a file of logged bytes.
    SBG CAN: ``INTERFACE:CHANNEL`` (``socketcan:can0``, ``slcan:/dev/ttyACM0``,
    ``socketcand:HOST:PORT:CHANNEL``, ``virtual:NAME``) or a CAN log file.
    With ``keep_raw`` the source keeps what it receives for
    :meth:`~sarmoco.drivers.source.Source.take_raw` (not a dataflash ``.bin``).

    Raises
    ------
    ConfigError
        If the protocol is not in :data:`INS_OPENERS` or the link does not fit it.
    DriverError
        If it cannot be opened.
    """
    opener = INS_OPENERS.get(cfg.ins.protocol)
    if opener is None:
        known = ", ".join(map(repr, INS_OPENERS))
        raise ConfigError(f"ins.protocol: {cfg.ins.protocol!r} is not one of {known}")
    source = opener(cfg.ins, cfg.ins.link if link is None else link)
    if keep_raw:
        source.keep_raw()
    return source


def _open_mavlink(ins: InsConfig, link: str) -> Source:
    """MAVLink: a pymavlink connection string, a ``.tlog`` or a dataflash ``.bin``."""
    from sarmoco.drivers.mavlink import open_mavlink

    return open_mavlink(
        link,
        leap_s=ins.gps_minus_utc_s,
        signing_key=bytes.fromhex(ins.signing_key_hex) if ins.signing_key_hex else None,
        baudrate=ins.baudrate,
        rates_hz=_mavlink_rates(ins.rate_hz),
        system_id=ins.mavlink_system_id,
    )


def _open_sbg(ins: InsConfig, link: str) -> Source:
    """SBG sbgECom: a serial device (``/dev/...``) or a file of logged bytes."""
    from sarmoco.drivers.sbg import SbgFileSource, SbgSerialSource

    if link.startswith("/dev/"):
        return SbgSerialSource(link, ins.baudrate, ins.gps_minus_utc_s)
    return SbgFileSource(link, ins.gps_minus_utc_s)


def _open_sbg_can(ins: InsConfig, link: str) -> Source:
    """SBG on CAN: ``INTERFACE:CHANNEL``, ``socketcand:HOST:PORT:CHANNEL`` or a CAN log file."""
    from sarmoco.drivers.can_source import CanLogSource, CanSource

    leap = ins.gps_minus_utc_s
    if link.endswith(CAN_LOG_SUFFIXES) and Path(link).is_file():
        return CanLogSource(link, leap)
    interface, _, channel = link.partition(":")
    if not channel:
        raise ConfigError(f"ins.link: {link!r} is not INTERFACE:CHANNEL or a CAN log file")
    if interface == "socketcand":
        host, port, chan = [*channel.rsplit(":", 2), "", ""][:3]
        if not port.isdigit():
            raise ConfigError(f"ins.link: {link!r} is not socketcand:HOST:PORT:CHANNEL")
        return CanSource.open("socketcand", chan or "can0", leap, host=host, port=int(port))
    return CanSource.open(interface, channel, leap)


def _mavlink_rates(rate_hz: float) -> dict[str, float]:
    """Messages the daemon asks the autopilot for, at the configured INS rate."""
    return {
        "LOCAL_POSITION_NED": rate_hz,
        "ATTITUDE_QUATERNION": rate_hz,
        "SYSTEM_TIME": 1.0,
    }


InsOpener = Callable[[InsConfig, str], Source]
"""Opens an INS link (``ins.link`` or a replayed file) with the ``ins`` settings."""

INS_OPENERS: dict[str, InsOpener] = {
    "mavlink": _open_mavlink,
    "sbg": _open_sbg,
    "sbg-can": _open_sbg_can,
}
"""Every INS protocol the daemon speaks, by its ``ins.protocol`` name."""
