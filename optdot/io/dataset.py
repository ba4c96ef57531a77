"""Large patterns as a partitioned Parquet dataset, read: ``NAME.parquet/`` holds one file
per tile and a manifest (the layout: :mod:`optdot.io.manifest`).

pandas (``pd.read_parquet("NAME.parquet")``), Dask (``dd.read_parquet``), DuckDB
(``read_parquet('NAME.parquet/*.parquet')``) and Polars (``pl.read_parquet``) read the
directory as it is: files starting with ``_`` are not data to them.

A dataset without its manifest (an interrupted write) is refused, and so is one whose
manifest is malformed or whose directory holds files the manifest does not list; parts
are checked against their row counts as read and against their checksums by
:meth:`Dataset.verify`. Writing is :mod:`optdot.io.dataset_write`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import PatternFileError, one_line
from ..files import sha256_file
from ..geometry.limits import validate_dots
from ..geometry.shapes import CIRCLE, Footprints, Kind
from ..pattern import Chunk, Pattern
from .footprints import file_footprints
from .manifest import MANIFEST, columns, manifest_kind, read_manifest

__all__ = ["MANIFEST", "Dataset", "is_dataset", "load_dataset", "open_dataset", "read_part_file"]


def is_dataset(path: str | Path) -> bool:
    """``path`` names a dataset (``.parquet``): a directory, or a name to create one."""
    return Path(path).suffix.lower() == ".parquet"


def read_part_file(path: Path, count: int, kind: Kind = CIRCLE) -> tuple[np.ndarray, Footprints]:
    """A part file's dots of ``kind``, ``(xy [n, 2] mm, footprints)``, holding ``count``
    rows (the columns of :func:`~optdot.io.manifest.columns`).

    Raises:
        PatternFileError: unreadable, not the kind's columns or not numbers, another
            row count, or a shaped dot that cannot be drawn
            (:func:`~optdot.io.footprints.file_footprints`).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = columns(kind)
    try:
        table = pq.read_table(path)
    except (OSError, ValueError, KeyError) as e:
        raise PatternFileError(f"{path}: not a readable Parquet part ({one_line(e)})") from None
    if tuple(table.column_names) != names:
        raise PatternFileError(
            f"{path}: columns {', '.join(table.column_names)}; {kind.name} dots are "
            f"{', '.join(names)}"
        )
    for name, field in zip(names, table.schema, strict=True):
        if not (pa.types.is_floating(field.type) or pa.types.is_integer(field.type)):
            raise PatternFileError(f"{path}: column {name} holds {field.type}, not numbers")
    if table.num_rows != count:
        raise PatternFileError(f"{path}: holds {table.num_rows} dots, the manifest says {count}")
    cols = [table.column(c).to_numpy().astype(np.float64, copy=False) for c in names]
    xy = np.column_stack(cols[:2])
    if kind.round:
        return xy, Footprints.circles(cols[2])
    return xy, file_footprints(path, kind, np.column_stack(cols[2:-1]), cols[-1])


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
        caps = np.array(m["caps_mm"], np.float64).reshape(-1, 3) if "caps_mm" in m else None
        rings = m.get("cap_rings_mm")
        rings = None if rings is None else np.array(rings, np.float64).reshape(-1, 2)
        margin = float(m.get("edge_margin_mm", 0.0))
        return Domain(geom, margin, False, str(self.path), caps=caps, cap_rings=rings)

    def outline_rings(self) -> list[np.ndarray]:
        """Boundary loops of the panel (outline and holes, or the box), mm."""
        if self.outline is not None:
            return self.outline.rings()
        x0, y0, x1, y1 = self.box
        return [np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=np.float64)]

    def chunks(self) -> Iterator[Chunk]:
        """``(tile, xy [n, 2], footprints)`` per part (what streamed exporters read)."""
        for k, part in enumerate(self.parts):
            xy, dots = self.read_part(k)
            yield tuple(part["tile"]), xy, dots  # type: ignore[misc]

    @property
    def kind(self) -> Kind:
        """The footprint kind of every dot (the manifest's ``shape``, else the circle)."""
        return manifest_kind(self.manifest)

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

    def read_part(self, k: int) -> tuple[np.ndarray, Footprints]:
        """Part ``k`` (position in :attr:`parts`): ``(xy [n, 2] mm, footprints)``."""
        part = self.parts[k]
        path = self.path / part["file"]
        xy, dots = read_part_file(path, part["count"], self.kind)
        u = self.uniform_diameter
        d = dots.diameter
        if u is not None and len(d) and not np.all(np.abs(d - u) <= 1e-9):
            i = int(np.argmax(np.abs(d - u) > 1e-9))
            raise PatternFileError(
                f"{path}: dot {i} has diameter {float(d[i]):.6g} mm, the manifest says every "
                f"dot is {u:.6g} mm"
            )
        return xy, dots

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
    doc = read_manifest(path)
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


def load_dataset(path: str | Path, box=None):
    """The whole dataset as one :class:`~optdot.pattern.Pattern` (parts in order), for
    patterns that fit in memory; checksums are verified.

    Raises:
        PatternFileError: see :func:`open_dataset`, :meth:`Dataset.verify`.
    """
    ds = open_dataset(path)
    ds.verify()
    xys, parts = [], []
    for _, xy, dots in ds.chunks():
        xys.append(xy)
        parts.append(dots)
    xy = np.concatenate(xys) if xys else np.zeros((0, 2))
    dots = Footprints.concat(parts, ds.kind)
    d = dots.diameter
    the_box = box or ds.box
    validate_dots(ds.path, xy, d, the_box)
    m = ds.manifest
    outline = ds.outline
    meta = dict(m.get("meta", {}))
    if isinstance(m.get("tiles"), dict) and m["tiles"].get("nx", 1) * m["tiles"].get("ny", 1) > 1:
        meta["tiling"] = {"xs": m["tiles"]["xs"], "ys": m["tiles"]["ys"]}
    shaped = None if ds.kind.round else dots
    return Pattern(xy=xy, diameter=d, box=the_box, meta=meta, outline=outline, dots=shaped)
