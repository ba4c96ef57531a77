"""Write a partitioned Parquet dataset (the layout: :mod:`optdot.io.manifest`),
all or nothing.

Parts go to a temporary directory beside the target, each is checked (rows, checksum) as
it is written, the manifest is written last, and only then is the directory put in place
(:func:`optdot.io.atomic.install_directory`: an atomic exchange with a previous dataset of
the same name, which is then removed). An interrupted or failed run leaves the previous
dataset as it was and no directory that looks complete. A directory is replaced only
when it is wholly an optdot dataset (:func:`check_dataset_target`).

A resumable run (``resume_key``) keeps its finished parts in a staging directory
(:func:`staging_dir`) with a record of each one, so the next run of the same job writes
only the rest.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ExportError, PatternFileError, one_line
from ..files import sha256_file
from ..geometry.orientation import degrees
from ..geometry.shapes import CIRCLE, Footprints, Kind
from ..runtime.stop import check_interrupt, note_on_stop
from .atomic import install_directory, short_name
from .dataset import open_dataset, read_part_file
from .manifest import (
    FORMAT,
    MANIFEST,
    VERSION,
    columns,
    manifest_kind,
    part_name,
    pattern_manifest,
    size_fields,
)

#: The record of a resumable run's finished parts, in its staging directory only.
RESUME = "_resume.json"
#: Prefix of the files :meth:`DatasetWriter.write_extra` keeps in a staging directory.
EXTRA = "_extra-"


def _table(xy: np.ndarray, dots: Footprints):
    """The part's table: the columns of :func:`~optdot.io.manifest.columns` for the
    dots' kind (angles in degrees, 1e-6°, as every file holds them)."""
    import pyarrow as pa

    values = [xy[:, 0], xy[:, 1], *(dots.size[:, c] for c in range(dots.size.shape[1]))]
    if not dots.kind.round:
        values.append(degrees(dots.angles))
    return pa.table(
        {
            name: pa.array(np.ascontiguousarray(v, dtype=np.float64), pa.float64())
            for name, v in zip(columns(dots.kind), values, strict=True)
        }
    )


@dataclass
class DatasetWriter:
    """Writes the parts of one dataset into a temporary (or staging) directory; use
    through :func:`write_dataset`, which writes the manifest and puts it in place."""

    tmp: Path
    target: Path
    parts: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: dots written per diameter, ``{diameter mm: count}`` (sizes are quantised: few keys).
    sizes: dict[float, int] = field(default_factory=dict)
    #: the run's identity when its parts are kept for a resume (see :func:`write_dataset`).
    resume_key: str | None = None
    #: parts a previous, interrupted run of the same job left, checked: ``{k: entry}``.
    resumed: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: what else a resumable run keeps beside its parts until it ends (the tiles' fields,
    #: which a resumed run would otherwise remake from every tile): ``{name: entry}``.
    extras: dict[str, dict[str, Any]] = field(default_factory=dict)

    def write_extra(self, name: str, arrays: dict[str, np.ndarray]) -> None:
        """Keep ``arrays`` under ``name`` for a resumed run (nothing without a resume
        key); a dataset never holds them."""
        if self.resume_key is None:
            return
        check_interrupt()
        path = self.tmp / f"{EXTRA}{name}.npz"
        try:
            with open(path, "wb") as fh:
                np.savez(fh, **arrays)
                fh.flush()
                os.fsync(fh.fileno())
            self.extras[name] = {"file": path.name, "sha256": sha256_file(path)}
            self._record()
        except OSError as e:
            raise ExportError(f"{self.target}: cannot write ({e.strerror})") from None

    def read_extra(self, name: str) -> dict[str, np.ndarray] | None:
        """What :meth:`write_extra` kept under ``name`` in an interrupted run of the same
        key, checked against its checksum when the staging directory was opened; None
        when there is none."""
        if name not in self.extras:
            return None
        with np.load(self.tmp / self.extras[name]["file"], allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    def read_resumed(self, k: int, kind: Kind = CIRCLE) -> tuple[np.ndarray, Footprints]:
        """A resumed part's dots of ``kind``: ``(xy [n, 2] mm, footprints)``."""
        entry = self.resumed[k]
        return read_part_file(self.tmp / entry["file"], entry["count"], kind)

    def _record(self) -> None:
        """Write the resume record (atomically): the key and every part written so far."""
        if self.resume_key is None:
            return
        doc = {
            "key": self.resume_key,
            "parts": {str(k): v for k, v in self.parts.items()},
            "extras": self.extras,
        }
        tmp = self.tmp / (RESUME + ".tmp")
        with open(tmp, "w") as fh:
            json.dump(doc, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.tmp / RESUME)

    def write_part(self, k: int, tile: tuple[int, int], xy: np.ndarray, dots: Footprints) -> None:
        """Write tile ``tile`` (part ``k``): ``xy`` ``[n, 2]`` mm and the dots' footprints
        (discs: :meth:`Footprints.circles`)."""
        import pyarrow.parquet as pq

        check_interrupt()
        if dots.n != len(xy):
            raise ValueError(f"part {k}: {len(xy)} positions but {dots.n} footprints")
        d = dots.diameter
        path = self.tmp / part_name(k)
        try:
            pq.write_table(_table(xy, dots), path, compression="zstd", write_statistics=True)
            rows = pq.ParquetFile(path).metadata.num_rows
        except OSError as e:
            raise ExportError(f"{self.target}: cannot write ({one_line(e)})") from None
        if rows != len(xy):
            raise ExportError(f"{self.target}: part {k} holds {rows} of {len(xy)} rows")
        self.parts[k] = {
            "file": path.name,
            "tile": list(tile),
            "count": len(xy),
            "sha256": sha256_file(path),
        }
        self._tally(d)
        try:
            self._record()
        except OSError as e:
            raise ExportError(f"{self.target}: cannot write ({e.strerror})") from None

    def _tally(self, d: np.ndarray) -> None:
        for v, c in zip(*np.unique(d, return_counts=True), strict=True):
            self.sizes[float(v)] = self.sizes.get(float(v), 0) + int(c)


def check_dataset_target(target: Path) -> None:
    """Refuse a target that is not a new name or an optdot dataset (never replaced).

    A directory is ours only when its own manifest says so (this format and version,
    well formed) and it holds nothing but that manifest and the parts it lists: a user's
    directory with a stray ``_manifest.json`` in it, or a dataset someone added files
    to, is left alone.
    """
    if target.is_symlink():
        raise ExportError(f"{target}: is a symbolic link; a dataset is replaced only in place")
    if target.exists() and not target.is_dir():
        raise ExportError(f"{target}: is a file, not a dataset directory")
    if target.is_dir():
        try:
            open_dataset(target, strict=True)
        except PatternFileError as e:
            raise ExportError(
                f"{target}: is a directory that is not an optdot dataset, never replaced ({e})"
            ) from None


def staging_dir(target: Path) -> Path:
    """Where a resumable run keeps its finished parts: ``.NAME.partial`` beside the target."""
    directory = target.parent if str(target.parent) else Path(".")
    return directory / f".{short_name(target.name)}.partial"


def _resume_record(staging: Path) -> dict[str, Any] | None:
    """The resume record of a staging directory, or None when it holds none."""
    try:
        doc = json.loads((staging / RESUME).read_text())
    except (OSError, ValueError):
        return None
    ok = isinstance(doc, dict) and isinstance(doc.get("key"), str)
    return doc if ok and isinstance(doc.get("parts"), dict) else None


def _open_staging(
    target: Path, key: str
) -> tuple[Path, dict[int, dict[str, Any]], dict[str, dict[str, Any]]]:
    """The staging directory of ``target``, the parts in it a previous run of the same
    ``key`` finished and what else it kept (each checked against its checksum; others
    are dropped). A staging directory of another run is cleared; a path of that name
    that is not ours (no resume record, a link, a file) is refused, never removed."""
    staging = staging_dir(target)
    if staging.is_symlink() or (staging.exists() and not staging.is_dir()):
        raise ExportError(f"{staging}: is in the way of the run's staging directory")
    parts: dict[int, dict[str, Any]] = {}
    extras: dict[str, dict[str, Any]] = {}
    if staging.is_dir():
        doc = _resume_record(staging)
        if doc is None:
            raise ExportError(
                f"{staging}: a directory that is not an optdot staging directory is in the "
                "way of the run's staging directory; move it"
            )
        if doc["key"] != key:  # another job, seed, plan or optdot: start over
            shutil.rmtree(staging)
        else:
            for k, entry in doc["parts"].items():
                try:  # an entry edited or damaged by hand is dropped: the part is remade
                    index = int(k)
                except (TypeError, ValueError):
                    continue
                if not isinstance(entry, dict):
                    continue
                f = staging / str(entry.get("file", ""))
                if (
                    f.is_file()
                    and f.parent == staging
                    and sha256_file(f) == entry.get("sha256")
                    and _rows(f) == entry.get("count")
                ):
                    parts[index] = entry
            kept = doc.get("extras")
            for name, entry in (kept if isinstance(kept, dict) else {}).items():
                if not isinstance(entry, dict):
                    continue
                f = staging / str(entry.get("file", ""))
                ours = f.name.startswith(EXTRA) and f.parent == staging
                if ours and f.is_file() and sha256_file(f) == entry.get("sha256"):
                    extras[str(name)] = entry
    try:
        staging.mkdir(mode=0o700, exist_ok=True)
    except OSError as e:
        raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    keep = {e["file"] for e in parts.values()} | {e["file"] for e in extras.values()} | {RESUME}
    for f in staging.iterdir():  # parts cut off by the interruption
        if f.name not in keep:
            if f.is_dir() and not f.is_symlink():
                raise ExportError(
                    f"{staging}: holds a directory {f.name!r} that is not the run's: move it "
                    f"out to resume, or delete {staging} to start over"
                )
            f.unlink()
    return staging, parts, extras


def _rows(path: Path) -> int:
    """Rows a part file holds by its own footer (-1 when it cannot be read)."""
    import pyarrow.parquet as pq

    try:
        return int(pq.ParquetFile(path).metadata.num_rows)
    except Exception:  # noqa: BLE001 - any damage: the part is remade
        return -1


@contextlib.contextmanager
def write_dataset(
    target: str | Path, manifest: dict[str, Any], resume_key: str | None = None
) -> Iterator[DatasetWriter]:
    """Write a dataset: yields a :class:`DatasetWriter`; on leaving the block the manifest
    (``manifest`` plus the parts) is written and the dataset put in place.

    With ``resume_key`` (the run's identity: job, inputs, seed, tiling, optdot's code),
    the parts are written into :func:`staging_dir` with a record of each one, and a failed
    or interrupted run leaves them there: the next run with the same key finds them in
    :attr:`DatasetWriter.resumed` and writes only the rest. Either way ``target`` changes
    only when the whole dataset is in place.

    Raises:
        ExportError: the target cannot be written or is a directory of something else;
            nothing at ``target`` changed.
    """
    target = Path(target)
    directory = target.parent if str(target.parent) else Path(".")
    check_dataset_target(target)
    resumed: dict[int, dict[str, Any]] = {}
    note_on_stop("")  # a note of an earlier run in this process is not this run's
    extras: dict[str, dict[str, Any]] = {}
    if resume_key is not None:
        tmp, resumed, extras = _open_staging(target, resume_key)
    else:
        try:
            tmp = Path(tempfile.mkdtemp(prefix=f".{short_name(target.name)}.", dir=directory))
        except OSError as e:
            raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    writer = DatasetWriter(tmp, target, resume_key=resume_key, resumed=resumed, extras=extras)
    writer.parts.update(resumed)
    try:
        writer._record()  # the staging directory is recognisably ours from the start
    except OSError as e:
        raise ExportError(f"{target}: cannot write ({e.strerror})") from None
    kind = manifest_kind(manifest)
    for k in resumed:
        writer._tally(writer.read_resumed(k, kind)[1].diameter)
    try:
        yield writer
        if resume_key is not None:  # a dataset holds only what it lists
            for entry in writer.extras.values():
                (tmp / entry["file"]).unlink(missing_ok=True)
            (tmp / RESUME).unlink(missing_ok=True)
        parts = [writer.parts[k] for k in sorted(writer.parts)]
        doc = {"format": FORMAT, "version": VERSION, **manifest, "parts": parts}
        if doc["diameter_mm"] is None:  # sizes known once written: uniform, median
            doc.update(size_fields(writer.sizes))
            if not kind.round:  # bounding discs: a median, never "every dot's size"
                doc["uniform_diameter_mm"] = None
        doc["n"] = sum(p["count"] for p in parts)
        data = json.dumps(doc, indent=1, sort_keys=True).encode() + b"\n"
        try:
            with open(tmp / MANIFEST, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            for p in parts:
                fd = os.open(tmp / p["file"], os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
        except OSError as e:
            raise ExportError(f"{target}: cannot write ({e.strerror})") from None
        if (tmp / MANIFEST).stat().st_size != len(data):
            raise ExportError(f"{target}: the manifest is incomplete (disk full?)")
        os.chmod(tmp, 0o755)
        check_interrupt()
        if target.is_dir():
            check_dataset_target(target)
        install_directory(tmp, target)
    except BaseException as e:
        nothing_to_resume = not writer.parts and not writer.extras  # e.g. no cluster
        if resume_key is None or (tmp / MANIFEST).exists() or nothing_to_resume:
            shutil.rmtree(tmp, ignore_errors=True)
        elif isinstance(e, KeyboardInterrupt) and writer.parts:
            note_on_stop(
                f"{len(writer.parts):,} finished tiles are kept in {tmp}: the same command "
                "resumes from them"
            )
        raise


def save_dataset(pattern, path: str | Path) -> None:
    """Write an in-memory pattern as a one-part dataset (discs, or shaped dots with their
    sizes and angles)."""
    with write_dataset(path, pattern_manifest(pattern)) as w:
        w.write_part(0, (0, 0), pattern.xy, pattern.shape)
