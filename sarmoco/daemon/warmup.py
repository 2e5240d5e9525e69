"""Compile the processing's numba kernels before the daemon reads its links.

numba compiles a kernel at its first call, or loads it from its cache (``cache=True``,
``NUMBA_CACHE_DIR`` in the systemd unit): tens of seconds on a loaded 2-core board for
an empty cache. Compiled at the first block, the radar ring overflowed meanwhile and
the watchdog missed its period (a 30-minute soak). ``sarmoco run`` calls
:func:`warm_up_kernels` first, before READY=1; while it runs the start-up timeout is
extended (``EXTEND_TIMEOUT_USEC``: systemd's watchdog is not armed before READY=1, its
``TimeoutStartSec`` is).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from sarmoco.daemon.config import Config
from sarmoco.daemon.sdnotify import Notifier
from sarmoco.processing.autofocus import splice
from sarmoco.processing.imaging import backprojection, ffbp, interp, presum

log = logging.getLogger(__name__)

EXTEND_EVERY_S = 5.0
"""Period of the ``EXTEND_TIMEOUT_USEC`` messages during the warm-up, s."""

EXTEND_BY_S = 30.0
"""Start-up time each message asks for, s (the next one comes long before it is used)."""


def kernel_warm_ups(cfg: Config) -> list[Callable[[], None]]:
    """The warm-up of each numba kernel that the configured processing calls.

    The direct backprojection always (FFBP falls back to it when it plans no stage); the
    FFBP kernels with ``imaging.method = "ffbp"``; the interpolation kernel with
    ``imaging.method = "rda"`` or ``"pfa"``; the pre-filter's with
    ``imaging.prefilter``; the autofocus phase removal's with ``autofocus.enabled``.
    None in array mode (``radar.mode = "array"``: numpy and scipy only).
    """
    if cfg.radar.mode == "array":
        return []
    warm_ups = [backprojection.warm_up]
    if cfg.imaging.method == "ffbp":
        warm_ups.append(ffbp.warm_up)
    if cfg.imaging.method in ("rda", "pfa"):
        warm_ups.append(interp.warm_up)
    if cfg.imaging.prefilter:
        warm_ups.append(presum.warm_up)
    if cfg.autofocus.enabled:
        warm_ups.append(splice.warm_up)
    return warm_ups


def _extend_until(done: threading.Event, notifier: Notifier) -> None:
    """Send ``EXTEND_TIMEOUT_USEC`` every :data:`EXTEND_EVERY_S` until ``done`` is set."""
    while True:
        notifier.extend_timeout(round(EXTEND_BY_S * 1e6))
        if done.wait(EXTEND_EVERY_S):
            return


def warm_up_kernels(cfg: Config, notifier: Notifier | None = None) -> float:
    """Compile (or load from numba's cache) the kernels of :func:`kernel_warm_ups`.

    Parameters
    ----------
    cfg : Config
        The configuration: which kernels the processing will call.
    notifier : Notifier, optional
        Told ``STATUS=`` and, every :data:`EXTEND_EVERY_S` from a thread (a compile
        holds the processing thread for seconds), ``EXTEND_TIMEOUT_USEC``.

    Returns
    -------
    float
        Wall time of the warm-up, s (also logged).
    """
    start = time.monotonic()
    done = threading.Event()
    keeper = None
    if notifier is not None and notifier.enabled:
        notifier.status("compiling the processing kernels")
        keeper = threading.Thread(
            target=_extend_until, args=(done, notifier), name="warm-up", daemon=True
        )
        keeper.start()
    warm_ups = kernel_warm_ups(cfg)
    try:
        for warm_up in warm_ups:
            warm_up()
    finally:
        done.set()
        if keeper is not None:
            keeper.join()
    took = time.monotonic() - start
    names = [f"{w.__module__.rsplit('.', 1)[-1]}" for w in warm_ups]
    log.info("kernels ready", extra={"kernels": names, "seconds": round(took, 2)})
    return took
