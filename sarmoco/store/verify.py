"""Does a store prove its own integrity? Every chunk read and its checksum checked.

Every array of a store ends its codecs with a CRC-32C of each chunk
(:data:`~sarmoco.store.schema.CHUNK_CHECKSUM`), and every chunk is written even when it
holds only the fill value. :func:`verify_store` reads every chunk a reader would read (rows
below a table's ``committed`` count, the tiles below the images' count, every chunk of the
other arrays) and reports each one that is missing, fails its checksum or does not decode,
by array and chunk index; and each group or array whose metadata cannot be read.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import zarr
from zarr.codecs import Crc32cCodec

from sarmoco.errors import RecorderError
from sarmoco.store import schema

DAMAGE = (OSError, ValueError, KeyError, IndexError, TypeError, RuntimeError)
"""What zarr, numcodecs and json raise on damaged bytes: a checksum that does not match or a
chunk of the wrong size (ValueError), a chunk that does not decompress (RuntimeError), a
metadata file that is not JSON (ValueError) or is gone (KeyError, FileNotFoundError)."""


@dataclass(frozen=True)
class ChunkFault:
    """One chunk (or node) of a store that cannot be trusted.

    Attributes
    ----------
    array : str
        Path of the array (or group) in the store, e.g. ``pulses/echo``.
    index : tuple of int
        Chunk index along each dimension (empty for a node whose metadata is damaged).
    problem : str
        ``missing``, ``checksum mismatch``, or what the decoder said.
    """

    array: str
    index: tuple[int, ...]
    problem: str

    def __str__(self) -> str:
        where = f" chunk {','.join(map(str, self.index))}" if self.index else ""
        return f"{self.array}{where}: {self.problem}"


@dataclass
class VerifyReport:
    """What :func:`verify_store` found.

    Attributes
    ----------
    arrays : int
        Arrays checked.
    chunks : int
        Chunks read.
    faults : list of ChunkFault
        Missing, corrupt or undecodable chunks, and unreadable nodes.
    unchecked : list of str
        Arrays whose chunks carry no checksum (stores written before the checksum was
        added): read, but a flipped bit there goes unseen.
    """

    arrays: int = 0
    chunks: int = 0
    faults: list[ChunkFault] = field(default_factory=list)
    unchecked: list[str] = field(default_factory=list)


def describe(exc: BaseException) -> str:
    """A decoder's failure in words: ``checksum mismatch`` or the exception's type and text."""
    text = str(exc)
    if "checksum" in text.lower():
        return "checksum mismatch"
    return f"undecodable ({type(exc).__name__}: {text})"


def chunk_rows(array: zarr.Array) -> int:
    """Rows per chunk along the first dimension of ``array``."""
    return int(array.chunks[0])


def read_chunk(array: zarr.Array, index: tuple[int, ...]) -> None:
    """Read chunk ``index`` of ``array`` through its codecs (checksum included).

    Raises
    ------
    ValueError, RuntimeError, OSError...
        Whatever zarr and numcodecs raise on a damaged chunk (see :data:`DAMAGE`).
    """
    region = tuple(
        slice(i * c, min((i + 1) * c, n))
        for i, c, n in zip(index, array.chunks, array.shape, strict=True)
    )
    array[region]


def chunk_present(root: Path, array: zarr.Array, index: tuple[int, ...]) -> bool:
    """Whether the file of chunk ``index`` exists in the store at ``root``."""
    return (root / array.path / array.metadata.encode_chunk_key(index)).is_file()


def _chunk_indices(array: zarr.Array, rows: int | None) -> Iterator[tuple[int, ...]]:
    """Indices of the chunks holding ``array``'s first ``rows`` rows (None: all)."""
    extent = list(array.shape)
    if rows is not None and extent:
        extent[0] = min(extent[0], rows)
    counts = [math.ceil(n / c) for n, c in zip(extent, array.chunks, strict=True)]
    return itertools.product(*(range(n) for n in counts))


def _walk(group: zarr.Group, report: VerifyReport, root: Path, prefix: str) -> None:
    """Check the arrays of ``group`` and of the groups below it: a table's arrays below its
    ``committed`` rows, the images' tiles below their ``committed`` count."""
    where = prefix or "/"
    try:
        members = sorted(group.members(), key=lambda kv: kv[0])
        attrs = dict(group.attrs)
        committed = schema.read_committed(attrs, where) if schema.COMMITTED_ATTR in attrs else None
    except (*DAMAGE, RecorderError) as exc:
        report.faults.append(ChunkFault(where, (), f"unreadable group ({exc})"))
        return
    images = prefix == schema.IMAGES_GROUP
    rows = None if images else committed
    for name, node in members:
        path = f"{prefix}/{name}" if prefix else name
        if isinstance(node, zarr.Group):
            if not (images and committed is not None and _tile_index(name) >= committed):
                _walk(node, report, root, path)  # a later tile was being formed: not stored
            continue
        report.arrays += 1
        codecs = getattr(node.metadata, "codecs", ())  # a zarr v2 array has none
        if not any(isinstance(c, Crc32cCodec) for c in codecs):
            report.unchecked.append(path)
        for index in _chunk_indices(node, rows):
            report.chunks += 1
            if not chunk_present(root, node, index):
                report.faults.append(ChunkFault(path, index, "missing"))
                continue
            try:
                read_chunk(node, index)
            except DAMAGE as exc:
                report.faults.append(ChunkFault(path, index, describe(exc)))


def _tile_index(name: str) -> int:
    digits = name.rsplit("_", 1)[-1]
    return int(digits) if digits.isdigit() else -1


def verify_store(path: str | Path) -> VerifyReport:
    """Read every chunk of the store at ``path`` that a reader would read.

    Returns
    -------
    VerifyReport
        Its ``faults`` empty when the store is intact.

    Raises
    ------
    RecorderError
        ``path`` is not a zarr v3 store (its root metadata unreadable).
    """
    root = Path(path)
    try:
        group = zarr.open_group(str(root), mode="r", zarr_format=3)
    except DAMAGE as exc:
        raise RecorderError(f"{root}: not a readable zarr v3 store: {exc}") from exc
    report = VerifyReport()
    _walk(group, report, root, "")
    return report
