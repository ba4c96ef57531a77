"""The manifest of an optdot dataset (``NAME.parquet/_manifest.json``): its schema, the
check both the reader and the writer trust, and the fields a run writes.

A dataset's layout::

    NAME.parquet/
        part-00000.parquet     columns x_mm, y_mm, diameter_mm (float64), one tile each,
        part-00001.parquet     tiles row by row (part k = tile (k % nx, k // nx))
        ...
        _manifest.json         format, job, seed, dot count, diameter, box, outline (WKB
                               hex), tiling, and per part: file, tile, count, sha256

Shaped dots (:mod:`optdot.geometry.shapes`): the manifest names the kind (``"shape":
"ellipse"``), the parts hold the columns of the pattern CSV for that kind (:func:`columns`:
``x_mm, y_mm``, the kind's sizes, ``angle_deg``), and ``diameter_mm`` is the median
bounding-disc diameter (``uniform_diameter_mm`` null). Without ``shape`` the dots are discs.

Reading is :mod:`optdot.io.dataset`, writing :mod:`optdot.io.dataset_write`; both
import this module and neither the other's internals, so "is this directory an optdot
dataset" (the reader's question, and the writer's before it replaces anything) has one
answer: :func:`read_manifest`.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import PatternFileError, one_line
from ..geometry.caps import caps_problem, rings_problem
from ..geometry.kinds import kind_of
from ..geometry.shapes import CIRCLE, KINDS, Kind

MANIFEST = "_manifest.json"
FORMAT = "optdot.dataset"
VERSION = 1
COLUMNS = ("x_mm", "y_mm", "diameter_mm")


def columns(kind: Kind) -> tuple[str, ...]:
    """The columns of a part (and of a pattern CSV) holding dots of ``kind``:
    :data:`COLUMNS` for discs; else ``x_mm, y_mm``, the kind's sizes in mm
    (``length_mm, width_mm[, corner_radius_mm]``) and ``angle_deg`` (the long axis from
    +x, counter-clockwise)."""
    if kind.round:
        return COLUMNS
    return ("x_mm", "y_mm", *(f"{p}_mm" for p in kind.params), "angle_deg")


def manifest_kind(doc: dict[str, Any]) -> Kind:
    """The footprint kind of a (checked) manifest's dots: its ``shape`` (with its
    ``shape_spec``), or the circle."""
    return kind_of(doc.get("shape", CIRCLE.name), doc.get("shape_spec"))


def part_name(k: int) -> str:
    """File name of part ``k``."""
    return f"part-{k:05d}.parquet"


def read_manifest(path: Path) -> dict[str, Any]:
    """The manifest of the dataset directory ``path``, parsed and checked (format,
    version, every field's name and type; not the parts on disk).

    Raises:
        PatternFileError: no manifest (not a dataset, or an incomplete write), too large,
            not JSON, another format or version, or a malformed field.
    """
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
    problem = manifest_problem(doc)
    if problem:
        raise PatternFileError(f"{mf}: malformed manifest ({problem})")
    return doc


#: Largest manifest read, bytes (a 10⁸-dot panel's is ~100 kB).
MAX_MANIFEST_BYTES = 64 << 20


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def manifest_problem(doc: dict[str, Any]) -> str | None:
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
    if "shape" in doc and (doc["shape"] not in KINDS or KINDS[doc["shape"]].round):
        return f"shape must be one of {', '.join(k for k, v in KINDS.items() if not v.round)}"
    if "shape" in doc:
        try:
            kind_of(doc["shape"], doc.get("shape_spec"))
        except ValueError as e:
            return f"shape_spec: {e}"
    if "shape" in doc and u is not None:
        return "uniform_diameter_mm must be null for shaped dots"
    if "outline_wkb_hex" in doc and not isinstance(doc["outline_wkb_hex"], str):
        return "outline_wkb_hex must be a string"
    if not _is_num(doc.get("edge_margin_mm", 0.0)):
        return "edge_margin_mm must be a number"
    if "caps_mm" in doc:
        caps = doc["caps_mm"]
        rows = isinstance(caps, list) and all(
            isinstance(r, list) and all(_is_num(v) for v in r) for r in caps
        )
        problem = caps_problem(np.array(caps, np.float64)) if rows else "caps_mm must be rows"
        if problem is not None:
            return problem.replace("caps", "caps_mm", 1)
        if "cap_rings_mm" in doc:
            rings = doc["cap_rings_mm"]
            ok = isinstance(rings, list) and all(
                isinstance(r, list) and all(_is_num(v) for v in r) for r in rings
            )
            table = np.array(rings, np.float64).reshape(-1, 2) if ok else None
            problem = rings_problem(table, np.array(caps)) if ok else "must be rows"
            if problem is not None:
                return f"cap_rings_mm: {problem}"
    elif "cap_rings_mm" in doc:
        return "cap_rings_mm without caps_mm"
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
    out = {"outline_wkb_hex": wkb, "edge_margin_mm": float(outline.edge_margin)}
    if outline.caps is not None:
        out["caps_mm"] = outline.caps.tolist()
        if outline.cap_rings is not None:
            out["cap_rings_mm"] = outline.cap_rings.tolist()
    return out


def size_fields(sizes: dict[float, int]) -> dict[str, Any]:
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


def manifest_of(
    job_name: str | None,
    seed: int | None,
    diameter: float | None,
    uniform: float | None,
    box,
    meta: dict[str, Any],
    outline=None,
    tiles: dict[str, Any] | None = None,
    kind: Kind = CIRCLE,
) -> dict[str, Any]:
    """The manifest fields of a dataset besides its parts (one tile = the box by default).
    ``diameter`` None: the nominal and uniform diameters are taken from the parts as
    they are written (:class:`DatasetWriter`). ``kind``: the dots' footprint kind
    (named only when not the circle: a disc dataset's manifest is as it always was)."""
    shaped = {} if kind.round else {"shape": kind.name}
    if kind.spec():
        shaped["shape_spec"] = kind.spec()
    return {
        **shaped,
        "job": job_name,
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
        kind=pattern.kind,
    )
