"""The independent end-to-end check, ``../shared/acceptance/run_blackbox.py``, on its cases.

The harness was written apart from the project, from physics and the public wire formats
(its own VITA 49.2 encoder, pymavlink ``.tlog``, sbgECom bytes), with motion from a real
ArduPilot flight. Each case builds its scenario, runs ``sarmoco replay`` on the files
(the project's interpreter, ``python -m sarmoco``) and scores the store's image against
truth: every target found with azimuth and range PSLR <= -12.5 dB and IRW <= 1.1 x
theory, in the right place (exit 0).

Each case is one subprocess of about 30-35 s of CPU; the classes are the scopes that the
suite's ``--dist loadscope`` workers share out. The figures in the docstrings are the
harness's verdicts when they were measured; docs/measurements/acceptance.md has the
current ones.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import tomli_w
import zarr

from tests.conftest import REPO

HARNESS = REPO.parent / "shared" / "acceptance" / "run_blackbox.py"
SCORE = HARNESS.with_name("score.py")

pytestmark = pytest.mark.acceptance

REPLAY_TIMEOUT_S = 300.0
"""The harness's limit on one replay (about 25 s on a quiet core), s."""

TRUE_GEOMETRY = ("--max-pos-err", "0.1")
"""The harness's geometry check: every target within 0.1 m of its truth position relative
to the others (after the common offset). Asked of the cases whose INS drifts less than that
over the targets' spread; elsewhere the INS's velocity error shears the image by more (the
same flight with the INS error scaled to 0: 0.017 m at most, docs/measurements/acceptance.md)."""


def run_case(workdir: Path, *options: str) -> None:
    """Run the harness on one case and require its pass (exit 0); print its verdict."""
    if not HARNESS.is_file():
        pytest.fail(f"the acceptance harness is not at {HARNESS}")
    cmd = [
        sys.executable, str(HARNESS), "--workdir", str(workdir), "--repo", str(REPO),
        "--sarmoco", f"{shlex.quote(sys.executable)} -m sarmoco",
        "--timeout", str(REPLAY_TIMEOUT_S), *options,
    ]  # fmt: skip
    done = subprocess.run(
        cmd, capture_output=True, text=True, cwd=REPO, timeout=REPLAY_TIMEOUT_S + 120
    )
    out = done.stdout + done.stderr
    verdicts = [line for line in out.splitlines() if "VERDICT" in line or "falls short" in line]
    print(f"{' '.join(options) or 'reference'}: exit {done.returncode}; " + " | ".join(verdicts))
    assert done.returncode == 0, "\n".join(out.strip().splitlines()[-25:])


def replay_with(workdir: Path, section: str, key: str, value: object) -> None:
    """Replay a case's files (``run_case`` left them in ``workdir``) with one key of the
    harness's configuration changed, and require the harness's pass on that store. The
    replay writes no north-up image (``imaging.north_up``): the tiles are what the key
    changes, and the harness would score a second image of them."""
    config = tomllib.loads((workdir / "sarmoco.toml").read_text())
    config.setdefault(section, {})[key] = value
    config.setdefault("imaging", {})["north_up"] = False
    changed = workdir / "changed.toml"
    changed.write_text(tomli_w.dumps(config))
    store = workdir / "changed.zarr"
    files = ["--radar", str(workdir / "radar.vrt"), "--nav", str(workdir / "nav.tlog")]
    replay = [sys.executable, "-m", "sarmoco", "replay", "--config", str(changed), *files]
    done = subprocess.run(
        [*replay, "--out", str(store)], capture_output=True, text=True, cwd=REPO,
        timeout=REPLAY_TIMEOUT_S,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    scored = subprocess.run(
        [sys.executable, str(SCORE), str(store), str(workdir / "truth.json")],
        capture_output=True, text=True, cwd=REPO, timeout=120,
    )  # fmt: skip
    verdict = [line for line in scored.stdout.splitlines() if "VERDICT" in line]
    print(f"{section}.{key} = {value!r}: exit {scored.returncode}; " + " | ".join(verdict))
    assert scored.returncode == 0, scored.stdout[-3000:]


def score_north_up_alone(workdir: Path) -> dict:
    """Score the north-up image of a case's store alone (a copy without the tiles): the
    harness compares it with the truth's NED positions, rotation-free, and gives each
    target's absolute error. Requires its pass (exit 0); returns its JSON."""
    store = workdir / "OUT.zarr"
    frame = zarr.open_group(str(store / "north_up" / "image_00"), mode="r").attrs["frame"]
    alone = workdir / "north_up_alone.zarr"
    shutil.copytree(store, alone, copy_function=os.link)  # links: nothing is rewritten
    shutil.rmtree(alone / "images")
    result = workdir / "north_up_alone.json"
    truth = workdir / "truth.json"
    scored = subprocess.run(
        [sys.executable, str(SCORE), str(alone), str(truth), "--json", str(result)],
        capture_output=True, text=True, cwd=REPO, timeout=120,
    )  # fmt: skip
    verdict = [line for line in scored.stdout.splitlines() if "VERDICT" in line or "frame" in line]
    print(f"north-up image alone ({frame}): exit {scored.returncode}; " + " | ".join(verdict))
    assert scored.returncode == 0, scored.stdout[-3000:]
    return {"frame": frame, **json.loads(result.read_text())}


class TestReferenceAndWire:
    """The reference flight, with the wire varied: stream ID, time base, sample type, INS."""

    def test_reference_with_the_stream_id_as_sent(self, tmp_path: Path) -> None:
        """Defaults (seed 7), the VITA stream ID 1 the harness sends, ``radar.stream_id = 1``.

        The replay's north-up image, scored alone, passes too, in NED: its coordinates are
        the INS's own local frame (LOCAL_POSITION_NED about the autopilot's EKF origin, the
        harness's origin), so every target lies within 3 m of its truth position: the
        INS's position error (1.1 m of offset and its drift) and the along-track shift of
        its velocity error (1.66-1.76 m in all on ``--crab 4``; the run frame would put
        them 128 m away)."""
        run_case(tmp_path, *TRUE_GEOMETRY)
        scored = score_north_up_alone(tmp_path)
        assert "the INS's own local frame" in scored["frame"]
        assert scored["info"]["frame"] == "NED"
        errors = [row["abs_err"] for row in scored["rows"]]
        assert len(errors) == 7 and max(errors) < 3.0, errors

    def test_reference_seed_3(self, tmp_path: Path) -> None:
        """Another draw of noise, INS error and target phases. Near the run's ends targets
        enter or leave the beam inside autofocus subapertures, where map drift answers with
        the edge of their echoes (85 to 520 Hz/s against rate errors of 1 to 3 Hz/s): worst
        azimuth PSLR -10.28 dB (T3) while such lines weighed in full.
        ``python -m bench.bench_blackbox_seeds 1-20`` runs the sweep of seeds."""
        run_case(tmp_path, "--seed", "3", *TRUE_GEOMETRY)

    def test_left_look_utc_float32(self, tmp_path: Path) -> None:
        run_case(
            tmp_path, "--look-side", "left", "--heading", "200", "--seed", "11",
            "--tsi", "utc", "--format", "float32", *TRUE_GEOMETRY,
        )  # fmt: skip

    def test_sbg_ins(self, tmp_path: Path) -> None:
        run_case(tmp_path, "--nav-format", "sbg", "--seed", "5", *TRUE_GEOMETRY)


class TestNavigationAndMotion:
    """ArduPilot's default streams; twice the motion and twice the INS error."""

    def test_global_position_int(self, tmp_path: Path) -> None:
        run_case(tmp_path, "--nav-messages", "global", "--seed", "3", *TRUE_GEOMETRY)

    def test_a_later_segment_of_the_flight(self, tmp_path: Path) -> None:
        """The same flight 6 s later: its track heads 0.4° off the nominal, the INS's
        attitude puts the beam 1.3° behind where the echoes put it (+26.6 Hz), and the
        pixels' squint interval, widened to cover both, spans 116 Hz of Doppler while the
        pre-filter keeps 77 Hz and decimates to 100 Hz. Taking pulses over all of it
        imaged every target's along-track ambiguity 48-54 m away (-29 dB), which the
        scoring then took for the targets: worst azimuth PSLR +7.88 dB."""
        run_case(tmp_path, "--log-start", "20")

    def test_a_later_segment_looking_left(self, tmp_path: Path) -> None:
        """The same segment mirrored. On the first processing block's heading, 0.76° off the
        course, the worst azimuth PSLR was -12.14 dB (T3); on 4 s of the INS log's course
        -12.78 dB."""
        run_case(tmp_path, "--log-start", "20", "--look-side", "left")

    def test_an_sbg_ins_looking_left_later_in_the_flight(self, tmp_path: Path) -> None:
        """An SBG INS names no origin for its positions, so the store's NED frame is its
        first fix, 160-185 m from the harness's origin. A north-up image about that point
        fitted the truth better than the tiles and failed the harness's frame check by
        184.86 m; the replay writes none there."""
        run_case(tmp_path, "--log-start", "30", "--look-side", "left", "--nav-format", "sbg",
                 "--seed", "55")  # fmt: skip

    def test_double_motion_and_ins_error(self, tmp_path: Path) -> None:
        """Twice the flight's motion and twice the INS error: -12.45 dB (T1) on the first
        block's heading, -12.81 dB on 4 s of the course."""
        run_case(
            tmp_path, "--pp-cross", "0.8", "--pp-vert", "0.48", "--ins-error-scale", "2",
            *TRUE_GEOMETRY,
        )  # fmt: skip


class TestCrab:
    """A crosswind: the body yawed against the track, the beam squinted with it."""

    def test_crab_4_deg(self, tmp_path: Path) -> None:
        """A 1.2 m/s crosswind at 17.5 m/s: the beam squinted 3.5° backward, its Doppler
        centroid (-106 Hz) aliased at 200 Hz PRF. Worst PSLR -12.98 dB (T4 azimuth)."""
        run_case(tmp_path, "--crab", "4")

    def test_crab_6_deg(self, tmp_path: Path) -> None:
        """A 6° crab: the run is three times the reference's length (1495 pulses), and its
        real flight's heading wanders up to 1.15° between apertures (no turn). Worst azimuth
        PSLR -13.13 dB (T3), IRW within 1.01 x theory."""
        run_case(tmp_path, "--crab", "6")

    @pytest.mark.bench  # a minute of CPU: docs/measurements/acceptance.md
    def test_gusts_that_swing_the_course_under_a_crab(self, tmp_path: Path) -> None:
        """Twice the motion and INS error at 6° of crab: the course swings 2.26° between
        the last two apertures (beam 1.91°) while the body's heading turns 0.98°. Taken for
        a turn, the last 0.59 s went unimaged and the farthest target kept two thirds of
        its aperture: azimuth IRW 1.37 x (T4)."""
        run_case(tmp_path, "--pp-cross", "0.8", "--pp-vert", "0.48", "--ins-error-scale", "2",
                 "--crab", "6", "--seed", "15")  # fmt: skip


class TestCrabLeft:
    """A crosswind from the other side, looking left: a class of its own so that two
    workers share the crab cases (each class is one worker's scope)."""

    def test_crab_minus_4_deg_left(self, tmp_path: Path) -> None:
        """The same crab looking left (body yawed toward the scene): worst azimuth PSLR
        -12.85 dB (T3); -12.47 dB with 0.4 s autofocus subapertures. Replayed again with
        tile PGA (``autofocus.pga``), which must keep the squinted beam's band: with a
        broadside band it found 5 of 7 targets, the best at -0.84 dB; -12.95 dB with it."""
        run_case(tmp_path, "--crab", "-4", "--look-side", "left", *TRUE_GEOMETRY)
        replay_with(tmp_path, "autofocus", "pga", True)

    def test_a_crab_where_the_attitude_misplaces_the_beam(self, tmp_path: Path) -> None:
        """A -3° crab looking left, 25 s into the flight: the attitude puts the beam 1.5 to
        2.3° behind where the echoes show it over the first two blocks (-131 to -141 Hz
        against -71 Hz), and those blocks' echoes, one target entering the beam, do not
        correlate enough to say so. With the attitude's beam alone the first target lit
        lost a quarter of its aperture: azimuth IRW 1.20 x (T1). The pixels now take the
        pointing uncertainty's wider beam until the echoes show where the beam is."""
        run_case(tmp_path, "--log-start", "25", "--crab", "-3", "--look-side", "left",
                 "--seed", "14")  # fmt: skip

    @pytest.mark.bench  # a minute of CPU: docs/measurements/acceptance.md
    def test_crab_minus_8_deg_left(self, tmp_path: Path) -> None:
        """Worst azimuth PSLR -12.89 dB (T6), IRW within 1.02 x theory (-12.44 dB on the
        first block's heading)."""
        run_case(tmp_path, "--crab", "-8", "--look-side", "left")
