"""Large patterns as a partitioned Parquet dataset: ``NAME.parquet/`` holds one file per tile
and a manifest.

Layout::

    NAME.parquet/
        part-00000.parquet     columns x_mm, y_mm, diameter_mm (float64), one tile each,
        part-00001.parquet     tiles row by row (part k = tile (k % nx, k // nx))
        ...
        _manifest.json         format, job, seed, dot count, diameter, box, outline (WKB
                               hex), tiling, and per part: file, tile, count, sha256

pandas (``pd.read_parquet("NAME.parquet")``), Dask (``dd.read_parquet``), DuckDB
(``read_parquet('NAME.parquet/*.parquet')``) and Polars (``pl.read_parquet``) read the
directory as it is: files starting with ``_`` are not data to them.

Writing is all-or-nothing: parts go to a temporary directory beside the target, each is
checked (rows, checksum) as it is written, the manifest is written last, and only then is
the directory put in place (an atomic exchange with a previous dataset of the same name,
which is then removed). An interrupted or failed run leaves the previous dataset as it was
and no directory that looks complete; a dataset without its manifest is refused on
reading.

Why one module of ~550 lines: the format is one concept, and its writer and reader share
the manifest's schema (:func:`_manifest_problem` is what both the reader and the
"is this directory ours to replace" check of the writer trust); split, each half would
import the other.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ExportError, PatternFileError, one_line
from ..files import sha256_file
from ..geometry.limits import validate_dots
from ..pattern import Pattern
from ..runtime.stop import check_interrupt
from .atomic import fsync_dir, short_name

MANIFEST = "_manifest.json"
#: The record of a resumable run's finished parts, in its staging directory only.
RESUME = "_resume.json"
FORMAT = "optdot.dataset"
VERSION = 1
COLUMNS = ("x_mm", "y_mm", "diameter_mm")


def is_dataset(path: str | Path) -> bool:
    """``path`` names a dataset (``.parquet``): a directory, or a name to create one."""
    return Path(path).suffix.lower() == ".parquet"


def part_name(k: int) -> str:
    return f"part-{k:05d}.parquet"


def _table(xy: np.ndarray, diameter: np.ndarray):
    import pyarrow as pa

    return pa.table(
        {
            "x_mm": pa.array(np.ascontiguousarray(xy[:, 0]), pa.float64()),
            "y_mm": pa.array(np.ascontiguousarray(xy[:, 1]), pa.float64()),
            "diameter_mm": pa.array(np.ascontiguousarray(diameter), pa.float64()),
        }
    )


def _read_part_file(path: Path, count: int) -> tuple[np.ndarray, np.ndarray]:
    """A part file's dots, ``(xy [n, 2], diameter [n])`` mm, holding ``count`` rows."""
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path, columns=list(COLUMNS))
    except (OSError, ValueError) as e:
        raise PatternFileError(f"{path}: not a readable Parquet part ({one_line(e)})") from None
    if table.num_rows != count:
        raise PatternFileError(f"{path}: holds {table.num_rows} dots, the manifest says {count}")
    cols = [table.column(c).to_numpy().astype(np.float64, copy=False) for c in COLUMNS]
    return np.column_stack(cols[:2]), cols[2]


@dataclass
class DatasetWriter:
    """Writes the parts of one dataset into a temporary directory; :meth:`commit` puts it
    in place. Use through :func:`write_dataset`."""

    tmp: Path
    target: Path
    parts: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: dots written per diameter, ``{diameter mm: count}`` (sizes are quantised: few keys).
    sizes: dict[float, int] = field(default_factory=dict)
    #: the run's identity when its parts are kept for a resume (see :func:`write_dataset`).
    resume_key: str | None = None
    #: parts a previous, interrupted run of the same job left, checked: ``{k: entry}``.
    resumed: dict[int, dict[str, Any]] = field(default_factory=dict)

    def read_resumed(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """A resumed part's dots: ``(xy [n, 2], diameter [n])``, mm."""
        return _read_part_file(self.tmp / self.resumed[k]["file"], self.resumed[k]["count"])

    def _record(self) -> None:
        """Write the resume record (atomically): the key and every part written so far."""
        if self.resume_key is None:
            return
        doc = {"key": self.resume_key, "parts": {str(k): v for k, v in self.parts.items()}}
        tmp = self.tmp / (RESUME + ".tmp")
        with open(tmp, "w") as fh:
            json.dump(doc, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.tmp / RESUME)

    def write_part(self, k: int, tile: tuple[int, int], xy: np.ndarray, diameter) -> None:
        """Write tile ``tile`` (part ``k``): ``xy`` ``[n, 2]`` mm, ``diameter`` mm (one or
        ``[n]``)."""
        import pyarrow.parquet as pq

        check_interrupt()
        d = np.broadcast_to(np.asarray(diameter, np.float64), (len(xy),))
        path = self.tmp / part_name(k)
        try:
            pq.write_table(_table(xy, d), path, compression="zstd", write_statistics=True)
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


def _renameat2_exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False where the
    system cannot."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError, TypeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange)
    return rc == 0


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


def _open_staging(target: Path, key: str) -> tuple[Path, dict[int, dict[str, Any]]]:
    """The staging directory of ``target`` and the parts in it a previous run of the same
    ``key`` finished (each checked against its checksum; others are dropped). A staging
    directory of another run is cleared; a path of that name that is not ours (no resume
    record, a link, a file) is refused, never removed."""
    staging = staging_dir(target)
    if staging.is_symlink() or (staging.exists() and not staging.is_dir()):
        raise ExportError(f"{staging}: is in the way of the run's staging directory")
    parts: dict[int, dict[str, Any]] = {}
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
                f = staging / str(entry.get("file", ""))
                if f.is_file() and f.parent == staging and sha256_file(f) == entry.get("sha256"):
                    parts[int(k)] = entry
    try:
        staging.mkdir(mode=0o700, exist_ok=True)
    except OSError as e:
        raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    keep = {e["file"] for e in parts.values()} | {RESUME}
    for f in staging.iterdir():  # parts cut off by the interruption
        if f.name not in keep:
            f.unlink()
    return staging, parts


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
    if resume_key is not None:
        tmp, resumed = _open_staging(target, resume_key)
    else:
        try:
            tmp = Path(tempfile.mkdtemp(prefix=f".{short_name(target.name)}.", dir=directory))
        except OSError as e:
            raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    writer = DatasetWriter(tmp, target, resume_key=resume_key, resumed=resumed)
    writer.parts.update(resumed)
    try:
        writer._record()  # the staging directory is recognisably ours from the start
    except OSError as e:
        raise ExportError(f"{target}: cannot write ({e.strerror})") from None
    for k in resumed:
        writer._tally(writer.read_resumed(k)[1])
    try:
        yield writer
        if resume_key is not None:
            (tmp / RESUME).unlink(missing_ok=True)  # a dataset holds only what it lists
        parts = [writer.parts[k] for k in sorted(writer.parts)]
        doc = {"format": FORMAT, "version": VERSION, **manifest, "parts": parts}
        if doc["diameter_mm"] is None:  # sizes known once written: uniform, median
            doc.update(_size_fields(writer.sizes))
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
            if not _renameat2_exchange(tmp, target):
                old = directory / f".{short_name(target.name)}.old"
                os.rename(target, old)
                os.rename(tmp, target)
                tmp = old
            shutil.rmtree(tmp, ignore_errors=True)  # the previous dataset
        else:
            os.rename(tmp, target)
        fsync_dir(directory)
    except BaseException:
        if resume_key is None or (tmp / MANIFEST).exists():
            shutil.rmtree(tmp, ignore_errors=True)
        raise


def _size_fields(sizes: dict[float, int]) -> dict[str, Any]:
    """``diameter_mm`` (the median, as ``np.median`` of every dot's) and
    ``uniform_diameter_mm`` (the one diameter, or None) of dots counted per diameter."""
    if not sizes:
        return {"diameter_mm": 0.0, "uniform_diameter_mm": None}
    values = np.array(sorted(sizes))
    cum = np.cumsum([sizes[v] for v in values])
    n = int(cum[-1])
    lo = values[np.searchsorted(cum, (n - 1) // 2, side="right")]
    hi = values[np.searchsorted(cum, n // 2, side="right")]
    uniform = float(values[0]) if len(values) == 1 else None
    return {"diameter_mm": float(0.5 * (lo + hi)), "uniform_diameter_mm": uniform}


@dataclass(frozen=True, eq=False)
class Dataset:
    """An opened dataset: its manifest, checked, and where its parts are.

    Attributes:
        path: the directory.
        manifest: the parsed manifest.
    """

    path: Path
    manifest: dict[str, Any]

    @property
    def n(self) -> int:
        return int(self.manifest["n"])

    @property
    def box(self) -> tuple[float, float, float, float]:
        return tuple(float(v) for v in self.manifest["box"])  # type: ignore[return-value]

    @property
    def parts(self) -> list[dict[str, Any]]:
        return self.manifest["parts"]

    @property
    def uniform_diameter(self) -> float | None:
        """The one diameter of every dot, mm, or None when sizes vary."""
        v = self.manifest.get("uniform_diameter_mm")
        return None if v is None else float(v)

    @property
    def nominal_diameter(self) -> float:
        return float(self.manifest["diameter_mm"])

    @cached_property
    def outline(self):
        """The panel outline (a :class:`~optdot.geometry.domain.Domain`), or None."""
        m = self.manifest
        if "outline_wkb_hex" not in m:
            return None
        import shapely

        from ..geometry.domain import Domain, orient_all

        try:
            geom = orient_all(shapely.from_wkb(m["outline_wkb_hex"]))
        except (shapely.errors.ShapelyError, TypeError, ValueError) as e:
            raise PatternFileError(
                f"{self.path}: bad outline in the manifest ({one_line(e)})"
            ) from None
        return Domain(geom, float(m.get("edge_margin_mm", 0.0)), False, str(self.path))

    def outline_rings(self) -> list[np.ndarray]:
        """Boundary loops of the panel (outline and holes, or the box), mm."""
        if self.outline is not None:
            return self.outline.rings()
        x0, y0, x1, y1 = self.box
        return [np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=np.float64)]

    def chunks(self) -> Iterator[tuple[tuple[int, int], np.ndarray, np.ndarray]]:
        """``(tile, xy [n, 2], diameter [n])`` per part (what streamed exporters read)."""
        return self.iter_parts()

    @property
    def part_counts(self) -> list[int]:
        """Dots per part, in part order."""
        return [int(p["count"]) for p in self.parts]

    @property
    def tiling(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(xs, ys)`` tile edges of a tiled run, mm, or None for one part."""
        tiles = self.manifest.get("tiles")
        if isinstance(tiles, dict) and tiles.get("nx", 1) * tiles.get("ny", 1) > 1:
            return np.asarray(tiles["xs"], float), np.asarray(tiles["ys"], float)
        return None

    @property
    def label(self) -> str:
        """The directory, for messages."""
        return str(self.path)

    @property
    def meta(self) -> dict[str, Any]:
        """The run's metadata as written with the dataset (job, seed, method, tiles)."""
        meta = self.manifest.get("meta")
        out = dict(meta) if isinstance(meta, dict) else {}
        if self.manifest.get("seed") is not None:
            out["seed"] = self.manifest["seed"]
        return out

    def read_part(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Part ``k`` (position in :attr:`parts`): ``(xy [n, 2], diameter [n])``, mm."""
        part = self.parts[k]
        path = self.path / part["file"]
        xy, d = _read_part_file(path, part["count"])
        u = self.uniform_diameter
        if u is not None and len(d) and not np.all(np.abs(d - u) <= 1e-9):
            i = int(np.argmax(np.abs(d - u) > 1e-9))
            raise PatternFileError(
                f"{path}: dot {i} has diameter {float(d[i]):.6g} mm, the manifest says every "
                f"dot is {u:.6g} mm"
            )
        return xy, d

    def iter_parts(self) -> Iterator[tuple[tuple[int, int], np.ndarray, np.ndarray]]:
        """``(tile, xy, diameter)`` of every part, in order."""
        for k, part in enumerate(self.parts):
            xy, d = self.read_part(k)
            yield tuple(part["tile"]), xy, d  # type: ignore[misc]

    def verify(self) -> None:
        """Check every part's checksum against the manifest.

        Raises:
            PatternFileError: a part is missing or changed.
        """
        for part in self.parts:
            path = self.path / part["file"]
            if not path.is_file():
                raise PatternFileError(f"{path}: part listed in the manifest is missing")
            if sha256_file(path) != part["sha256"]:
                raise PatternFileError(f"{path}: checksum differs from the manifest")


def open_dataset(path: str | Path, strict: bool = False) -> Dataset:
    """Open a dataset and check its manifest (not yet the parts' checksums).

    Args:
        path: the dataset directory.
        strict: also refuse any entry of the directory the manifest does not list
            (hidden ones too): a directory about to be replaced must be wholly ours.
            Without it, a visible file besides the parts is still refused, as Parquet
            readers would read it as data.

    Raises:
        PatternFileError: not a directory, no manifest (an incomplete write), a manifest
            that is not this format or whose fields have the wrong type, or files the
            manifest does not list.
    """
    path = Path(path)
    if path.is_file():
        raise PatternFileError(
            f"{path}: is a single file; an optdot dataset is a directory (NAME.parquet/) "
            "with a manifest"
        )
    if not path.is_dir():
        raise PatternFileError(f"{path}: dataset directory not found")
    mf = path / MANIFEST
    if not mf.is_file():
        raise PatternFileError(f"{path}: no {MANIFEST} (not an optdot dataset, or incomplete)")
    try:
        if mf.stat().st_size > MAX_MANIFEST_BYTES:
            raise PatternFileError(
                f"{mf}: {mf.stat().st_size:,} bytes, larger than any optdot manifest"
            )
        doc = json.loads(mf.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise PatternFileError(f"{mf}: not a readable manifest ({one_line(e)})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise PatternFileError(f"{mf}: not an optdot dataset manifest")
    if doc.get("version") != VERSION:
        raise PatternFileError(f"{mf}: dataset version {doc.get('version')!r} is not {VERSION}")
    problem = _manifest_problem(doc)
    if problem:
        raise PatternFileError(f"{mf}: malformed manifest ({problem})")
    listed = {p["file"] for p in doc["parts"]} | {MANIFEST}
    for entry in sorted(os.listdir(path)):
        if entry in listed:
            continue
        if strict or not entry.startswith(("_", ".")):
            raise PatternFileError(
                f"{path / entry}: is not a part the manifest lists"
                + ("" if strict else " (Parquet readers would read it as data)")
            )
    return Dataset(path, doc)


#: Largest manifest read, bytes (a 10⁸-dot panel's is ~100 kB).
MAX_MANIFEST_BYTES = 64 << 20


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _manifest_problem(doc: dict[str, Any]) -> str | None:
    """What is wrong with a manifest's fields (names and types), or None."""
    box = doc.get("box")
    if not (isinstance(box, list) and len(box) == 4 and all(_is_num(v) for v in box)):
        return "box must be 4 numbers"
    if not (box[0] < box[2] and box[1] < box[3]):
        return "box is empty"
    for key in ("diameter_mm",):
        if not (_is_num(doc.get(key)) and doc[key] > 0):
            return f"{key} must be a number > 0"
    u = doc.get("uniform_diameter_mm")
    if u is not None and not (_is_num(u) and u > 0):
        return "uniform_diameter_mm must be null or a number > 0"
    if not isinstance(doc.get("meta", {}), dict):
        return "meta must be an object"
    if "outline_wkb_hex" in doc and not isinstance(doc["outline_wkb_hex"], str):
        return "outline_wkb_hex must be a string"
    if not _is_num(doc.get("edge_margin_mm", 0.0)):
        return "edge_margin_mm must be a number"
    tiles = doc.get("tiles")
    if tiles is not None:
        ok = isinstance(tiles, dict) and all(
            _is_int(tiles.get(k)) and tiles[k] >= 1 for k in ("nx", "ny")
        )
        ok = ok and all(
            isinstance(tiles.get(k), list) and all(_is_num(v) for v in tiles[k])
            for k in ("xs", "ys")
        )
        if not ok:
            return "tiles must hold nx, ny (integers) and xs, ys (numbers)"
    parts = doc.get("parts")
    if not isinstance(parts, list):
        return "parts must be a list"
    files = set()
    for i, p in enumerate(parts):
        ok = isinstance(p, dict) and isinstance(p.get("file"), str)
        ok = ok and _PART_NAME.fullmatch(p["file"]) is not None and p["file"] not in files
        ok = ok and _is_int(p.get("count")) and p["count"] >= 0
        ok = ok and isinstance(p.get("tile"), list) and len(p["tile"]) == 2
        ok = ok and all(_is_int(v) and v >= 0 for v in p["tile"])
        ok = ok and isinstance(p.get("sha256"), str) and len(p["sha256"]) == 64
        if not ok:
            return f"part {i} needs file (part-NNNNN.parquet, once), count, tile, sha256"
        files.add(p["file"])
    if not (_is_int(doc.get("n")) and doc["n"] == sum(p["count"] for p in parts)):
        return "n must be the sum of the parts' counts"
    return None


_PART_NAME = re.compile(r"part-\d{5,}\.parquet")


def outline_hex(outline) -> dict[str, Any]:
    """Manifest fields of a panel outline (a Domain, or None for the box): WKB as hex,
    bit-exact, and the edge margin."""
    if outline is None:
        return {}
    import shapely

    wkb = shapely.to_wkb(outline.geometry, byte_order=1, hex=True)
    return {"outline_wkb_hex": wkb, "edge_margin_mm": float(outline.edge_margin)}


def load_dataset(path: str | Path, box=None):
    """The whole dataset as one :class:`~optdot.pattern.Pattern` (parts in order), for
    patterns that fit in memory; checksums are verified.

    Raises:
        PatternFileError: see :func:`open_dataset`, :meth:`Dataset.verify`.
    """
    ds = open_dataset(path)
    ds.verify()
    xys, ds_ = [], []
    for _, xy, d in ds.iter_parts():
        xys.append(xy)
        ds_.append(d)
    xy = np.concatenate(xys) if xys else np.zeros((0, 2))
    d = np.concatenate(ds_) if ds_ else np.zeros(0)
    the_box = box or ds.box
    validate_dots(ds.path, xy, d, the_box)
    m = ds.manifest
    outline = ds.outline
    meta = dict(m.get("meta", {}))
    if isinstance(m.get("tiles"), dict) and m["tiles"].get("nx", 1) * m["tiles"].get("ny", 1) > 1:
        meta["tiling"] = {"xs": m["tiles"]["xs"], "ys": m["tiles"]["ys"]}
    return Pattern(xy=xy, diameter=d, box=the_box, meta=meta, outline=outline)


def manifest_of(
    job: str | None,
    seed: int | None,
    diameter: float | None,
    uniform: float | None,
    box,
    meta: dict[str, Any],
    outline=None,
    tiles: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The manifest fields of a dataset besides its parts (one tile = the box by default).
    ``diameter`` None: the nominal and uniform diameters are taken from the parts as
    they are written (:class:`DatasetWriter`)."""
    return {
        "job": job,
        "seed": seed,
        "diameter_mm": None if diameter is None else float(diameter),
        "uniform_diameter_mm": uniform,
        "box": [float(v) for v in box],
        "meta": meta,
        "tiles": tiles or {"nx": 1, "ny": 1, "xs": [box[0], box[2]], "ys": [box[1], box[3]]},
        **outline_hex(outline),
    }


def pattern_manifest(pattern) -> dict[str, Any]:
    """Manifest fields of an in-memory pattern (one part)."""
    m = pattern.meta
    return manifest_of(
        m.get("job"),
        m.get("seed"),
        pattern.nominal_diameter,
        pattern.uniform_diameter,
        pattern.box,
        m,
        pattern.outline,
    )


def save_dataset(pattern, path: str | Path) -> None:
    """Write an in-memory pattern as a one-part dataset."""
    with write_dataset(path, pattern_manifest(pattern)) as w:
        w.write_part(0, (0, 0), pattern.xy, pattern.diameter)
