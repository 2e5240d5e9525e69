"""``sarmoco batch``: ground reprocessing of recordings on a dask.distributed cluster.

Each recording (a store written by ``sarmoco run``/``replay``, or a ``.vrt`` radar
file with its INS log) is reprocessed in two kinds of task:

1. **Front end**, one task per recording: the replay of :func:`replay_store` /
   :func:`replay_files` with imaging deferred. Alignment, range compression, INS
   compensation, the sliding-subaperture autofocus and the azimuth pre-filter run
   once over the whole recording, exactly as in a single-process replay; they write
   the output store's tables (pulses, nav, motion, autofocus) and keep, per segment,
   the pulses the tile imager would take in a scratch store
   (:mod:`sarmoco.app.imaging_stream`). They cannot be cut into blocks: the
   autofocus pins its unobservable constant and linear terms over the first
   ``autofocus.pin_window_s`` of a segment and integrates from there, and D_los
   integrates from the segment's start, so a block started mid-segment would carry
   another phase.
2. **Imaging blocks**, many per segment: ``--tiles-per-block`` consecutive tiles,
   backprojected, refined by tile PGA, and written into tiles of the output store
   that were created beforehand (region writes: each block fills only its tiles'
   arrays). A block replays the imager calls whose pulses' beam footprints reach its
   tiles (a pixel takes the pulses whose beam sees it), and one tile more each side
   when tile PGA is on (it focuses a tile with its raw neighbours). Its tiles then get
   the same pulses, cut into the same calls and chunks, in the same order as in the single-process
   replay: the images agree to float rounding (the tests find them bit-equal).

Backprojection is the bulk of the work in a full-size run; the front ends of many
recordings also run side by side.

A worker that dies (killed, out of memory, its machine lost) costs only the tasks it
held: the scheduler runs them again on another worker (or on the one its nanny
restarts). A front end run again starts its output and scratch stores anew (the batch
refuses outputs that exist before it starts, so what it finds there is its own
unfinished attempt); an imaging block run again rewrites its own tiles. A front end's
result is released once its blocks are planned, so a later worker death never runs it
again under blocks that are writing. The stores come out as from an undisturbed run.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import zarr

from sarmoco.app.imaging_stream import SegmentStream, StreamRecorder
from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.focuser import tile_imaging
from sarmoco.daemon.runner import replay_files, replay_store
from sarmoco.daemon.tables import RunSummary, recorded_tile_metrics
from sarmoco.errors import ConfigError, ProcessingError
from sarmoco.products.northup import write_north_up_images
from sarmoco.store import schema
from sarmoco.store.recorder import create_tile, write_tile

LOOPBACK = "127.0.0.1"
"""The only address a local cluster binds."""


@dataclass(frozen=True)
class Recording:
    """One recording to reprocess and the store to write.

    Attributes
    ----------
    out : Path
        Output store to create.
    store : Path or None
        A store recorded by ``sarmoco run`` or ``replay`` (with raw echoes).
    radar, nav : Path or None
        Or a VITA 49.2 radar file and its INS log.
    """

    out: Path
    store: Path | None = None
    radar: Path | None = None
    nav: Path | None = None

    @property
    def scratch(self) -> Path:
        """The scratch store of its deferred pulses (removed when the batch succeeds)."""
        return self.out.with_name(self.out.name + ".batch-scratch")


@dataclass(frozen=True)
class FrontEnd:
    """What a recording's front-end task gives back: its totals and segment streams."""

    recording: Recording
    summary: RunSummary
    streams: list[SegmentStream]


@dataclass(frozen=True)
class ImageBlock:
    """Tiles ``first_tile .. last_tile`` of one segment, and where they go in the store.

    Attributes
    ----------
    out : Path
        Output store.
    stream : SegmentStream
        The segment.
    first_tile, last_tile : int
        Tile indices of the segment's layout (inclusive).
    store_index : int
        Store index of the segment's first tile (``stream.tiles[0]``).
    """

    out: Path
    stream: SegmentStream
    first_tile: int
    last_tile: int
    store_index: int


def front_end(cfg: Config, recording: Recording) -> FrontEnd:
    """Replay a recording with imaging deferred (a task): tables into the output store,
    the pulses to image into its scratch store. The output store is marked not
    ``complete`` until its tiles are written (:func:`finish_store`).

    Stores left at ``recording.out`` and its scratch path by an earlier attempt of this
    task (on a worker that died) are removed first: :func:`run_batch` refuses outputs
    that exist before the batch, so only an attempt of the batch can have left them.
    """
    for leftover in (recording.out, recording.scratch):
        shutil.rmtree(leftover, ignore_errors=True)
    sink = StreamRecorder(recording.scratch)
    if recording.store is not None:
        summary = replay_store(cfg, recording.store, recording.out, False, sink)
    else:
        assert recording.radar is not None and recording.nav is not None
        summary = replay_files(cfg, recording.radar, recording.nav, recording.out, False, sink)
    root = zarr.open_group(str(recording.out), mode="r+", zarr_format=3)
    root.update_attributes({schema.COMPLETE_ATTR: False})
    return FrontEnd(recording, summary, sink.streams())


def block_span_m(block: ImageBlock, with_pga: bool) -> tuple[float, float]:
    """Along-track span (imaging x, m) that the footprints of the pulses a block needs
    meet: its tiles, and one tile more each side with tile PGA."""
    extra = 1 if with_pga else 0
    first, last = block.first_tile - extra, block.last_tile + extra
    length = block.stream.layout.tile_length_m
    return first * length, (last + 1) * length


def image_block(cfg: Config, block: ImageBlock) -> list[tuple[int, dict[str, float]]]:
    """Form, refine and write one block's tiles (a task); their store indices and metrics.

    The imager replays the segment's calls that reach the block and forms only the
    block's tiles and, with tile PGA, their neighbours (context only, not written).
    """
    imager, tile_pga = tile_imaging(cfg, cfg.radar.params())
    stream = block.stream
    imager.layout = stream.layout  # with the segment's share of the ground (keep)
    extra = 1 if tile_pga is not None else 0
    imager.only = range(block.first_tile - extra, block.last_tile + extra + 1)
    formed = []
    for call in stream.calls_within(*block_span_m(block, tile_pga is not None)):
        formed += imager.add(*stream.read(call))
    formed += imager.close()
    if tile_pga is not None:
        formed = tile_pga.push(formed) + tile_pga.flush()
    images = zarr.open_group(str(block.out / schema.IMAGES_GROUP), mode="r+", zarr_format=3)
    track = schema.encode_reference_track(stream.track)
    written = []
    for tile in formed:
        if not block.first_tile <= tile.index <= block.last_tile:
            continue
        index = block.store_index + tile.index - stream.tiles[0]
        metrics = recorded_tile_metrics(tile)
        group = images[schema.tile_name(index)]
        assert isinstance(group, zarr.Group)
        write_tile(group, tile.image(), tile.t0_ns, tile.t1_ns, metrics, track)
        written.append((index, metrics))
    return written


def plan_blocks(result: FrontEnd, tiles_per_block: int) -> list[ImageBlock]:
    """Create every tile of a recording's output store (axes, empty data) and cut each
    segment's tiles into blocks of ``tiles_per_block``, in store order (segment by
    segment, tiles by index, as the single-process replay records them)."""
    images = zarr.open_group(
        str(result.recording.out / schema.IMAGES_GROUP), mode="r+", zarr_format=3
    )
    blocks, index = [], 0
    for stream in result.streams:
        tiles = stream.tiles
        for k in tiles:
            grid = stream.layout.grid(k)
            create_tile(images, index + k - tiles[0], grid.axis0_m, grid.axis1_m)
        for k0 in tiles[::tiles_per_block]:
            k1 = min(k0 + tiles_per_block - 1, tiles[-1])
            blocks.append(ImageBlock(result.recording.out, stream, k0, k1, index))
        index += len(tiles)
    return blocks


def finish_store(result: FrontEnd, written: dict[int, dict[str, float]]) -> RunSummary:
    """Commit the tiles, write the run metrics with them, mark the store complete, and
    remove the scratch store; the run's summary.

    Raises
    ------
    ProcessingError
        A tile created by :func:`plan_blocks` was not written by any block.
    """
    planned = sum(len(stream.tiles) for stream in result.streams)
    missing = sorted(set(range(planned)) - set(written))
    if missing:
        raise ProcessingError(
            f"batch: {result.recording.out}: tiles {missing} were not formed by their blocks"
        )
    summary = replace(
        result.summary,
        tiles=len(written),
        tile_metrics=[written[i] for i in sorted(written)],
    )
    root = zarr.open_group(str(result.recording.out), mode="r+", zarr_format=3)
    images = root[schema.IMAGES_GROUP]
    images.update_attributes({schema.COMMITTED_ATTR: len(written)})
    metrics = json.loads(json.dumps(summary.as_dict(), default=str))
    root.update_attributes({"metrics": metrics, schema.COMPLETE_ATTR: True})
    shutil.rmtree(result.recording.scratch, ignore_errors=True)
    return summary


def run_batch(
    client: Any,
    cfg: Config,
    recordings: Sequence[Recording],
    tiles_per_block: int = 16,
    progress: bool = True,
) -> list[RunSummary]:
    """Reprocess recordings on a dask.distributed client; their summaries, in order.

    Front ends are submitted at once; each recording's imaging blocks as soon as its
    front end is done. Each task's future is released as soon as its result is read, so
    the scheduler never recomputes a finished task whose worker dies later (a front end
    run again would start its store anew under the blocks writing into it).

    Raises
    ------
    ConfigError
        An output store (or its scratch store) exists already.
    """
    from distributed import as_completed

    at_least_one("--tiles-per-block", tiles_per_block)
    refuse_existing(recordings)
    fronts = [client.submit(front_end, cfg, r, pure=False) for r in recordings]
    owner: dict[Any, int] = {f: i for i, f in enumerate(fronts)}
    results: list[FrontEnd | None] = [None] * len(recordings)
    written: list[dict[int, dict[str, float]]] = [{} for _ in recordings]
    pending = as_completed(fronts)
    del fronts
    total, done = len(recordings), 0
    for future in pending:
        i, value = owner.pop(future), future.result()
        future.release()
        done += 1
        if isinstance(value, FrontEnd):
            results[i] = value
            blocks = [
                client.submit(image_block, cfg, b, pure=False)
                for b in plan_blocks(value, tiles_per_block)
            ]
            owner.update({f: i for f in blocks})
            pending.update(blocks)
            total += len(blocks)
        else:
            written[i].update(value)
        if progress:
            _progress(done, total)
    if progress:
        sys.stderr.write("\n")
    summaries = []
    for result, tiles in zip(results, written, strict=True):
        assert result is not None
        summaries.append(finish_store(result, tiles))
    return summaries


@contextmanager
def cluster_client(scheduler: str | None, workers: int, dashboard: bool = True) -> Iterator[Any]:
    """A client of the cluster at ``scheduler``, or of a local cluster of ``workers``
    worker processes (one thread each) bound to 127.0.0.1 only (dashboard on a free
    loopback port, or none)."""
    from distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    at_least_one("--workers", workers)
    with (
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            dashboard_address=f"{LOOPBACK}:0" if dashboard else None,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def check_batch_memory(cfg: Config, tiles_per_block: int, local_workers: int | None) -> None:
    """Refuse a batch whose worker processes cannot hold their buffers.

    A worker runs one task at a time: a front end (a replay, with a run's buffers,
    :func:`~sarmoco.daemon.resources.plan`) or an imaging block (its ``tiles_per_block``
    tiles, and a neighbour each side with tile PGA). Both are counted, for each of the
    ``local_workers`` processes of a local cluster within the memory limit
    (``limits.memory_mib``, or this machine's memory), or for one worker of a cluster
    started apart (``local_workers`` None; its workers' machines are not known here).

    Raises
    ------
    ConfigError
        Naming the key of the largest buffer, its bytes, the total and the limit.
    """
    from sarmoco.daemon.resources import COMPLEX64_BYTES, Buffer, check_memory, memory_limit, plan

    im = cfg.imaging
    tiles = tiles_per_block + (2 if cfg.autofocus.pga else 0)
    nx, ny = math.ceil(im.tile_length_m / im.pixel_m), math.ceil(im.swath_m / im.pixel_m)
    block = Buffer(
        "imaging block",
        ("--tiles-per-block", "imaging.pixel_m", "imaging.tile_length_m", "imaging.swath_m"),
        tiles * nx * ny * COMPLEX64_BYTES,
        f"{tiles} tiles x {nx} x {ny} complex64 pixels",
    )
    limit, where = memory_limit(cfg)
    copies = local_workers or 1
    if local_workers:
        where += f"; shared by --workers {local_workers}"
    options = {"--tiles-per-block": tiles_per_block}
    check_memory([*plan(cfg), block], limit, where, copies, cfg=cfg, options=options)


def refuse_existing(recordings: Sequence[Recording]) -> None:
    """Refuse output (or scratch) stores that exist (ConfigError naming them)."""
    taken = [p for r in recordings for p in (r.out, r.scratch) if p.exists()]
    if taken:
        raise ConfigError(f"batch: {', '.join(map(str, taken))} exist(s); a batch never overwrites")


def at_least_one(option: str, value: int) -> None:
    """Refuse a count below 1 (ConfigError naming the option)."""
    if value < 1:
        raise ConfigError(f"batch: {option} {value} is not >= 1")


def dashboard_text(client: Any) -> str:
    """Where the scheduler serves its dashboard, or why it serves none.

    Without bokeh in the scheduler's environment its HTTP server answers ``/health`` and
    ``/metrics`` only; the text says so rather than give a link to pages that are not there.
    """
    if "dashboard" not in client.scheduler_info().get("services", {}):
        return "dashboard: none (the scheduler was started without one)"
    if not client.run_on_scheduler(_has_bokeh):
        return (
            f"dashboard: none (bokeh is not installed where the scheduler runs; pip install"
            f" bokeh to serve it at {client.dashboard_link})"
        )
    return f"dashboard: {client.dashboard_link}"


def _has_bokeh() -> bool:
    """Whether bokeh can be imported here (run on the scheduler)."""
    import importlib.util

    return importlib.util.find_spec("bokeh") is not None


def _progress(done: int, total: int) -> None:
    width = 40
    filled = round(width * done / max(total, 1))
    sys.stderr.write(f"\rbatch [{'#' * filled}{'.' * (width - filled)}] {done}/{total} tasks")
    sys.stderr.flush()


# -- command line -----------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``sarmoco batch``."""
    parser.add_argument("recordings", nargs="*", type=Path, help="stores to reprocess")
    parser.add_argument("--config", required=True, help="TOML configuration file")
    parser.add_argument("--radar", type=Path, help="a VITA 49.2 radar file (.vrt) ...")
    parser.add_argument("--nav", type=Path, help="... and its INS log")
    parser.add_argument(
        "--out", required=True, type=Path,
        help="store to create (one recording) or folder of RECORDING-NAME.zarr stores",
    )  # fmt: skip
    parser.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT",
        help="address of a running dask scheduler (`dask scheduler`, its workers started by "
        "`dask worker`); default: a local cluster of --workers processes on 127.0.0.1",
    )  # fmt: skip
    parser.add_argument("--workers", type=int, default=2, help="local worker processes")
    parser.add_argument(
        "--tiles-per-block", type=int, default=16, help="tiles per imaging task (default 16)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def recordings_of(args: argparse.Namespace) -> list[Recording]:
    """The recordings the command line names, each with its output store."""
    if (args.radar is None) != (args.nav is None):
        raise ConfigError("batch: give both --radar FILE.vrt and --nav FILE, or neither")
    inputs: list[tuple[str, Recording]] = [
        (p.stem, Recording(Path(), store=p)) for p in args.recordings
    ]
    if args.radar is not None:
        inputs.append((args.radar.stem, Recording(Path(), radar=args.radar, nav=args.nav)))
    if not inputs:
        raise ConfigError("batch: give recordings (stores), or --radar FILE.vrt --nav FILE")
    if len(inputs) == 1:
        return [replace(inputs[0][1], out=args.out)]
    names = [name for name, _ in inputs]
    if len(set(names)) != len(names):
        raise ConfigError(f"batch: recordings with the same name {names} would share an output")
    return [replace(r, out=args.out / f"{name}.zarr") for name, r in inputs]


def run_command(args: argparse.Namespace) -> int:
    """Run ``sarmoco batch``."""
    recordings = recordings_of(args)
    at_least_one("--tiles-per-block", args.tiles_per_block)
    at_least_one("--workers", args.workers)
    refuse_existing(recordings)
    cfg = load_config(args.config)
    check_batch_memory(cfg, args.tiles_per_block, None if args.scheduler else args.workers)
    start = time.monotonic()
    with cluster_client(args.scheduler, args.workers) as client:
        print(dashboard_text(client), file=sys.stderr)
        summaries = run_batch(client, cfg, recordings, args.tiles_per_block, not args.quiet)
    for r, s in zip(recordings, summaries, strict=True):
        print(f"{r.out}: {s.pulses_processed} pulses focused, {s.tiles} tiles")
        for line in write_north_up_images(r.out).lines():
            print(f"{r.out}: {line}")
    print(f"batch: {len(recordings)} recording(s) in {time.monotonic() - start:.1f} s")
    return 0
