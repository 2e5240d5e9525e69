"""Shared fixtures: where the repository and the shared data live."""

from __future__ import annotations

import os
from pathlib import Path
from typing import NoReturn

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root."""
    return REPO


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository (real data nobody on the team made)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


def unavailable(msg: str) -> NoReturn:
    """Skip the calling test for want of ``msg`` on a developer's machine, but fail it under
    ``CI=true``: ``.ci/run`` gives every test what it needs (root, mounts, cgroups, Chromium,
    systemd-analyze, the shared data), and a CI run must not pass by skipping."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(msg)
    pytest.skip(msg)


def shared_files(subdir: str, pattern: str, count: int) -> list[Path]:
    """The ``count`` files of ``../shared/data/<subdir>`` that match ``pattern``, sorted.

    Where they are missing the calling test is skipped on a developer's machine, but fails
    under ``CI=true``: a CI run must not pass by skipping the real-data tests.
    """
    folder = SHARED_DATA / subdir
    files = sorted(folder.glob(pattern))
    if len(files) != count:
        unavailable(f"{count} files {pattern!r} expected in {folder}, found {len(files)}")
    return files


@pytest.fixture(scope="session")
def gotcha_files() -> list[Path]:
    """The two 1° files of AFRL GOTCHA pass 1 HH (234 pulses)."""
    return shared_files("gotcha", "data_3dsar_pass1_az00*_HH.mat", 2)


# `make test` runs the suite in three phases: every test but these on three pytest-xdist
# workers (`-m "not realtime"`); then these, a module at a time on two workers (`-m
# "realtime and not exclusive"`); then the EXCLUSIVE ones alone, one after the other.
# Realtime tests start `sarmoco run` / `sarmoco sim --serve` processes or play in real
# time, and judge what happened within wall-clock budgets (UDP pulses taken before the
# ring fills, watchdog pings, /status answering): beside a CPU-bound worker they fail, as
# the CI runs on a loaded machine did, while two of them, each mostly waiting on the
# clock, share the machine. The key is the file; its value names the test functions
# concerned (empty: every test of the file). tests/test_realtime_marks.py fails when a
# module that starts a live run or a daemon is missing here.
REALTIME: dict[str, tuple[str, ...]] = {
    # a live run (run_loopback) watched in headless Chromium
    "tests/app/test_live_browser.py": (),
    # `dask scheduler` and `dask worker` processes; a worker SIGKILLed while it holds a task
    "tests/app/test_batch.py": ("test_a_worker_killed_mid_job_costs_only_its_tasks",),
    # `sarmoco bench`: simulator and daemon live on loopback, pulses and latency judged
    "tests/app/test_bench.py": ("test_bench_prints_sane_figures_and_removes_its_folder",),
    # `sarmoco run` processes: SIGKILL at random moments, sd_notify watchdog, /status; on
    # file links to their end (two modules, so that the realtime phase runs them side by side)
    "tests/daemon/test_daemon_process.py": (),
    "tests/daemon/test_daemon_files.py": (),
    # `sarmoco run` with its MAVLink camera component, driven by a pymavlink ground station
    "tests/daemon/test_camera_daemon.py": (),
    # `sarmoco run` in array mode: the simulator's MIMO scene over UDP and MAVLink
    "tests/daemon/test_array_live.py": (),
    # live runs over every link (run_loopback); the replay test reads their stores
    "tests/daemon/test_end_to_end.py": (),
    # daemons under faults: bus-off windows, full or frozen disks, the OOM killer and
    # SIGTERM beside CPU hogs, INS link faults and latency, radar loss, hostile datagrams
    "tests/daemon/test_faults_can_bus.py": (),
    "tests/daemon/test_faults_host.py": (),
    # `sarmoco run` under libfaketime: its wall clock steps while the pulses flow
    "tests/daemon/test_faults_host_clock.py": (),
    "tests/daemon/test_faults_ins.py": (),
    "tests/daemon/test_faults_ins_link.py": (),
    "tests/daemon/test_faults_ins_long.py": (),
    "tests/daemon/test_faults_radar.py": (),
    "tests/daemon/test_faults_radar_loss.py": (),
    # a live run over UDP whose focuser is slowed: every pulse recorded, none without navigation
    "tests/daemon/test_ingest_keeps_up.py": (),
    "tests/daemon/test_faults_wire.py": (  # its replay and focuser tests are not live
        "test_duplicated_reordered_lost_datagrams_cost_no_focus",
        "test_overload_costs_pulses_not_the_process",
    ),
    # 60 writers SIGKILLed at random moments (also a bench)
    "tests/daemon/test_faults_power.py": (
        "test_sigkill_at_60_random_moments_keeps_committed_rows",
    ),
    # the live page during a `sarmoco run`: renders at most once a second, CPU share
    "tests/daemon/test_live_page.py": ("test_live_page_during_a_run",),
    # 12 writer processes SIGKILLed at random moments within 2 s
    "tests/store/test_recorder.py": (
        "test_sigkill_at_random_moments_leaves_committed_rows_intact",
    ),
    # a `sarmoco run` SIGKILLed mid-run: what the store holds after the kill
    "tests/store/test_recorder_crash_bound.py": (),
    # a short soak (also a bench)
    "tests/daemon/test_soak_short.py": (),
    # 40 stalled clients: a GET answered within 0.5 s, each stall closed within 1.5 s
    "tests/daemon/test_status.py": (
        "test_stalled_and_oversized_requests_do_not_stall_the_endpoint",
    ),
    # a 2.5 s autopilot thread answering TIMESYNC: bounds, request timing, sample counts
    "tests/drivers/test_mavlink.py": (
        "test_udp_round_trip_timesync_rates",
        "test_the_autopilot_is_chosen_not_the_first_system_heard",
        "test_a_wall_clock_step_moves_no_sample",
        "test_timesync_settles_quickly_then_slows_down",
        "test_signing_rejects_unsigned_and_bad_keys",
    ),
    # `sarmoco sim --serve` processes playing in real time, every pulse and sample judged
    "tests/sim/test_emit_cli.py": (),
    # playing pinned to the host clock, TIMESYNC bounds judged
    "tests/sim/test_emit_mavlink.py": ("test_udp_live_timesync_and_rates", "test_stream_links"),
    # a `sarmoco run` process whose sockets are listed
    "tests/test_security.py": ("test_daemon_listens_only_on_the_configured_addresses",),
}


EXCLUSIVE: dict[str, tuple[str, ...]] = {
    # load the machine themselves or measure rates and CPU shares: alone, one at a time
    "tests/app/test_live_browser.py": (),  # headless Chromium beside a live run
    "tests/app/test_batch.py": ("test_a_worker_killed_mid_job_costs_only_its_tasks",),
    "tests/app/test_bench.py": ("test_bench_prints_sane_figures_and_removes_its_folder",),
    # CPU hogs, memory limits, the OOM killer, the watchdog's pings while the store is
    # frozen; the refused writes too: beside another test, a /status poll during a
    # read-only store's refusals was once reset by the daemon (cause not found)
    "tests/daemon/test_faults_host.py": (),
    # the wall clock's steps must land while the autopilot's stream flows: beside another
    # test the /status poll that starts them came late, and the last two fell after it
    "tests/daemon/test_faults_host_clock.py": (),
    "tests/daemon/test_ingest_keeps_up.py": (  # a focuser spinning with the GIL held (the
        # file run whose recording stalls reads as fast as the disk allows: no pace judged)
        "test_a_slow_focuser_loses_no_pulse_and_leaves_none_without_navigation",
    ),
    "tests/daemon/test_live_page.py": ("test_live_page_during_a_run",),  # its CPU share
    "tests/daemon/test_soak_short.py": (),
    "tests/daemon/test_status.py": (
        "test_stalled_and_oversized_requests_do_not_stall_the_endpoint",
    ),
    "tests/drivers/test_mavlink.py": (  # TIMESYNC bounds judged in real time
        "test_udp_round_trip_timesync_rates",
        "test_the_autopilot_is_chosen_not_the_first_system_heard",
        "test_a_wall_clock_step_moves_no_sample",
        "test_timesync_settles_quickly_then_slows_down",
    ),
    "tests/sim/test_emit_mavlink.py": ("test_udp_live_timesync_and_rates",),
}
"""The realtime tests that run alone (a subset of :data:`REALTIME`)."""


def _listed(table: dict[str, tuple[str, ...]], item: pytest.Item) -> bool:
    names = table.get(item.path.relative_to(REPO).as_posix())
    return names is not None and (not names or getattr(item, "originalname", "") in names)


LONGEST_FIRST: tuple[str, ...] = (
    "tests/test_acceptance_blackbox.py",  # cases of 13-44 s each, a class per scope
    "tests/daemon/test_platform_geometry.py",
    "tests/test_codebase.py",  # mypy
    "tests/test_install.py",  # two virtual environments
    "tests/app/test_export.py",
    "tests/app/test_array_mode.py",
    "tests/processing/array/test_array_dem.py",
    "tests/processing/imaging/test_rda_tiles.py",
    "tests/daemon/test_segments.py",
    "tests/products/test_motion_estimates.py",
    # the realtime phase's (its tests only; 25-60 s each)
    "tests/daemon/test_array_live.py",
    "tests/daemon/test_daemon_files.py",
    "tests/daemon/test_faults_ins_link.py",
    "tests/daemon/test_end_to_end.py",
    "tests/daemon/test_camera_daemon.py",
    "tests/sim/test_emit_cli.py",
    "tests/daemon/test_daemon_process.py",
    "tests/daemon/test_faults_radar.py",
    "tests/daemon/test_faults_radar_loss.py",
)
"""The modules whose tests take longest, longest first (pytest's ``--durations``, summed
per module, on a 2-core machine): those of the first phase of `make test`, then those of
the realtime phase. They are collected first, the rest in pytest's order: the first two
phases hand the scopes out in collection order (``--no-loadscope-reorder``), so their
workers end together instead of one running a long scope alone at the end."""


def _collection_rank(item: pytest.Item) -> int:
    path = item.path.relative_to(REPO).as_posix()
    return LONGEST_FIRST.index(path) if path in LONGEST_FIRST else len(LONGEST_FIRST)


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Put the modules of :data:`LONGEST_FIRST` first (a stable sort: the rest keep their
    order); mark the tests of :data:`REALTIME` ``realtime``, those of :data:`EXCLUSIVE` also
    ``exclusive``."""
    items.sort(key=_collection_rank)
    for item in items:
        if _listed(REALTIME, item):
            item.add_marker(pytest.mark.realtime)
            if _listed(EXCLUSIVE, item):
                item.add_marker(pytest.mark.exclusive)
