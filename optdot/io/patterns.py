"""Pattern files written by ``optdot generate`` and read by ``export`` and ``qa``.

* CSV: header ``x_mm,y_mm,diameter_mm``, one dot a row, 6 decimals (1 nm). Shaped dots:
  ``x_mm,y_mm``, the kind's sizes (``length_mm,width_mm`` for an ellipse, then
  ``corner_radius_mm`` for a rounded rectangle) and ``angle_deg`` (the long axis from +x,
  counter-clockwise, 1e-6°); the header names the kind. A kind made per job (a
  polygon) is named on a line before the header, ``# {"shape": "polygon",
  "vertices_mm": [[x, y], ...]}`` (JSON after ``# ``).
* NPZ: arrays ``xy`` ``[n, 2]`` (mm), ``diameter`` (mm: a 0-d array when every dot has
  the same size, else ``[n]``), ``box`` ``[4]`` (mm) and ``meta`` (JSON text), plus
  ``outline_wkb``/``edge_margin`` for outlines (and ``caps`` ``[m, 3]``, ``x, y,
  diameter`` mm, when the outline has caps: :mod:`optdot.geometry.caps`, with
  ``cap_rings`` ``[k, 2]`` ``r_in, r_out`` mm when they are graded); shaped dots
  hold ``shape`` (the kind's name), ``size`` (mm, ``[k]`` or ``[n, k]``) and
  ``angle_deg`` ``[n]`` instead of ``diameter`` (and ``shape_spec``, JSON text, for a kind
  made per job). A zip with fixed timestamps so equal
  patterns give equal bytes.
"""

from __future__ import annotations

import io
import json
import warnings
import zipfile
from dataclasses import replace
from pathlib import Path

import numba as nb
import numpy as np
import shapely

from ..errors import ExportError, PatternFileError, one_line
from ..files import input_problem
from ..geometry.caps import caps_problem, rings_problem
from ..geometry.domain import Domain, orient_all
from ..geometry.kinds import kind_of
from ..geometry.limits import validate_dots
from ..geometry.orientation import degrees
from ..geometry.shapes import KINDS, Footprints, Kind
from ..pattern import Pattern
from .atomic import atomic_path, expect_size
from .dataset import load_dataset
from .dataset_write import save_dataset
from .footprints import file_footprints

CSV_HEADER = "x_mm,y_mm,diameter_mm"


def csv_header(kind: Kind) -> str:
    """The CSV header of dots of ``kind`` (:data:`CSV_HEADER` for circles)."""
    if kind.round:
        return CSV_HEADER
    return ",".join(["x_mm", "y_mm", *(f"{p}_mm" for p in kind.params), "angle_deg"])


#: Each header a pattern CSV may have, and its kind (a kind made per job is named on
#: the line before, :func:`csv_preamble`).
CSV_KINDS = {csv_header(k): k for k in KINDS.values() if not k.derived}
#: What starts the line naming a kind made per job before a CSV's header.
CSV_SPEC = "# "


def csv_preamble(kind: Kind) -> str:
    """The line before a CSV's header naming ``kind`` when the header cannot (a kind
    made per job: its name and :meth:`~optdot.geometry.kinds.base.Kind.spec` as JSON),
    else nothing."""
    spec = kind.spec()
    if not spec:
        return ""
    return CSV_SPEC + json.dumps({"shape": kind.name, **spec}, separators=(", ", ": ")) + "\n"


def save_pattern(pattern: Pattern, path: str | Path) -> None:
    """Write ``pattern`` to ``.csv`` or ``.npz`` atomically (see module doc).

    Raises:
        ExportError: unknown suffix or unwritable path.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        save_dataset(pattern, path)
        return
    if suffix not in (".csv", ".npz"):
        raise ExportError(
            f"{path}: pattern files are .csv, .npz or .parquet, not {suffix or 'no suffix'!r}"
        )
    if suffix == ".csv":
        write_csv(pattern, path)
        return
    with atomic_path(path, _verify_npz(path)) as tmp:
        _write_npz(pattern, tmp)


def write_csv(pattern: Pattern, path: str | Path, opts=None) -> None:
    """Write the pattern's CSV atomically, its size checked before it replaces anything
    (``opts``: the export's options, none apply).

    Raises:
        ExportError: the pattern prints caps over its LEDs (a CSV holds dots only).
    """
    if pattern.outline is not None and pattern.outline.caps is not None:
        raise ExportError(
            f"{path}: the pattern prints caps over its LEDs, which a CSV of dots cannot "
            "hold; write .npz or .parquet, or a mask (gds, oas, dxf)"
        )
    data = pattern_csv_bytes(pattern)
    with atomic_path(path, expect_size(len(data), str(path))) as tmp:
        tmp.write_bytes(data)


def _verify_npz(path: Path):
    """Check a written NPZ: every member's CRC (the zip reads back whole)."""

    def check(tmp: Path) -> None:
        try:
            with zipfile.ZipFile(tmp) as zf:
                bad = zf.testzip()
        except (zipfile.BadZipFile, EOFError) as e:
            raise ExportError(f"{path}: the written file does not read back ({e})") from None
        if bad is not None:
            raise ExportError(f"{path}: member {bad} of the written file is corrupt")

    return check


def pattern_csv_bytes(pattern: Pattern) -> bytes:
    """The CSV text of a pattern, as bytes (``x,y,d`` in mm with 6 decimals = 1 nm;
    shaped dots: ``x,y``, sizes, angle in degrees)."""
    dots = pattern.dots
    if dots is None:
        data = np.column_stack([pattern.xy, pattern.diameter])
    else:
        data = np.column_stack([pattern.xy, dots.size, degrees(dots.angles)])
    head = csv_preamble(pattern.kind) + csv_header(pattern.kind) + "\n"
    return head.encode("ascii") + format_fixed6(data)


def format_fixed6(values: np.ndarray) -> bytes:
    """Rows of ``values`` (``[n, k]`` float) as comma-separated ``%.6f`` text lines.

    Same text as ``np.savetxt(fmt="%.6f", delimiter=",")`` for values that are exact to
    1e-6 (positions are rounded to 1 nm), ten times faster.
    """
    values = np.ascontiguousarray(values, dtype=np.float64)
    if values.size == 0:
        return b""
    micro = np.round(values * 1e6)
    if not np.all(np.abs(micro) < 9e17):
        raise ValueError("value too large for fixed-point CSV")
    return _format_micro(micro.astype(np.int64), np.signbit(values)).tobytes()


@nb.njit(cache=True)
def _format_micro(micro, negative):  # pragma: no cover - compiled
    n, k = micro.shape
    out = np.empty(n * k * 28, np.uint8)
    pos = 0
    digits = np.empty(20, np.uint8)
    for i in range(n):
        for c in range(k):
            v = micro[i, c]
            if negative[i, c]:
                out[pos] = 45  # '-'
                pos += 1
            v = abs(v)
            whole = v // 1000000
            frac = v % 1000000
            m = 0
            while True:
                digits[m] = 48 + whole % 10
                whole //= 10
                m += 1
                if whole == 0:
                    break
            for q in range(m - 1, -1, -1):
                out[pos] = digits[q]
                pos += 1
            out[pos] = 46  # '.'
            pos += 1
            for q in range(5, -1, -1):
                out[pos + q] = 48 + frac % 10
                frac //= 10
            pos += 6
            out[pos] = 44 if c < k - 1 else 10  # ',' or newline
            pos += 1
    return out[:pos]


def _write_npz(pattern: Pattern, path: Path) -> None:
    arrays = {"xy": pattern.xy}
    dots = pattern.dots
    if dots is None:
        u = pattern.uniform_diameter
        arrays["diameter"] = np.array(u) if u is not None else pattern.diameter
    else:
        one = bool(np.all(dots.size == dots.size[:1]))
        arrays["shape"] = np.array(dots.kind.name)
        if dots.kind.spec():
            arrays["shape_spec"] = np.array(json.dumps(dots.kind.spec()))
        arrays["size"] = dots.size[0] if one else dots.size
        arrays["angle_deg"] = degrees(dots.angles)
    arrays["box"] = np.array(pattern.box)
    arrays["meta"] = np.array(json.dumps(pattern.meta, sort_keys=True))
    if pattern.outline is not None:
        # WKB keeps every coordinate bit-exact (WKT text does not)
        wkb = shapely.to_wkb(pattern.outline.geometry, byte_order=1)
        arrays["outline_wkb"] = np.frombuffer(wkb, dtype=np.uint8)
        arrays["edge_margin"] = np.array(pattern.outline.edge_margin)
        if pattern.outline.caps is not None:
            arrays["caps"] = pattern.outline.caps
            if pattern.outline.cap_rings is not None:
                arrays["cap_rings"] = pattern.outline.cap_rings
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, buf.getvalue())


def load_pattern(path: str | Path, box: tuple[float, float, float, float] | None = None) -> Pattern:
    """Read a pattern written by :func:`save_pattern`.

    Args:
        path: ``.csv`` or ``.npz``.
        box: panel box to use when the file does not hold one (CSV); default is the
            dots' bounding box grown by one radius.

    Raises:
        PatternFileError: missing, unreadable or malformed file (one line, names the file).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix != ".parquet":  # a dataset is a directory, checked when opened
        problem = input_problem(path, 1 << 62 if suffix == ".npz" else None)
        if problem is not None:
            raise PatternFileError(f"{path}: pattern {problem}")
    elif not path.exists():
        raise PatternFileError(f"{path}: pattern file not found")
    if suffix == ".parquet":
        return load_dataset(path, box)
    if suffix == ".npz":
        return _load_npz(path, box)
    if suffix == ".csv":
        return _load_csv(path, box)
    raise PatternFileError(
        f"{path}: unknown pattern format {suffix!r} (use .csv, .npz or .parquet)"
    )


def _load_csv(path: Path, box: tuple[float, float, float, float] | None) -> Pattern:
    try:
        # utf-8-sig: a byte-order mark (spreadsheets write one) is read over
        with open(path, encoding="utf-8-sig") as fh:
            header = fh.readline().strip()
            kind = None
            if header.startswith(CSV_SPEC.strip()):
                kind = _csv_kind(path, header)
                header = fh.readline().strip()
                if header != csv_header(kind):
                    raise PatternFileError(
                        f"{path}: line 2: header must be {csv_header(kind)!r} for "
                        f"{kind.name} dots, got {header[:60]!r}"
                    )
            elif header not in CSV_KINDS:
                raise PatternFileError(
                    f"{path}: line 1: header must be {CSV_HEADER!r} (or a shaped dot's, "
                    f"{', '.join(repr(h) for h in CSV_KINDS if h != CSV_HEADER)}), "
                    f"got {header[:60]!r}"
                )
            with warnings.catch_warnings():  # "no data" is reported below, in one line
                warnings.simplefilter("ignore", UserWarning)
                data = np.loadtxt(fh, delimiter=",", ndmin=2, dtype=np.float64)
    except (UnicodeDecodeError, ValueError) as e:
        raise PatternFileError(f"{path}: malformed pattern CSV ({one_line(e)})") from None
    except OSError as e:
        raise PatternFileError(f"{path}: cannot read ({e.strerror})") from None
    if data.size == 0:
        raise PatternFileError(f"{path}: no dots in the file")
    kind = kind or CSV_KINDS[header]
    if data.shape[1] != header.count(",") + 1:
        raise PatternFileError(
            f"{path}: expected {header.count(',') + 1} columns ({header}), got {data.shape[1]}"
        )
    if kind.round:
        return _validated(path, data[:, :2], data[:, 2], box, {})
    dots = file_footprints(path, kind, data[:, 2:-1], data[:, -1])
    return _validated(path, data[:, :2], dots.diameter, box, {}, dots)


def _csv_kind(path: Path, line: str) -> Kind:
    """The kind a CSV's first line names (:func:`csv_preamble`).

    Raises:
        PatternFileError: not JSON, or not a kind.
    """
    try:
        doc = json.loads(line[len(CSV_SPEC.strip()) :])
        if not isinstance(doc, dict) or not isinstance(doc.get("shape"), str):
            raise ValueError('must be a JSON object with "shape"')
        return kind_of(doc["shape"], {k: v for k, v in doc.items() if k != "shape"})
    except (ValueError, RecursionError, OverflowError) as e:
        raise PatternFileError(f"{path}: line 1: not the dots' kind ({one_line(e)})") from None


def _check_npz_sizes(path: Path, z) -> None:
    """Refuse an archive whose arrays would not fit in memory before any is inflated: a
    compressed member of 1.6 MB may declare gigabytes of zeros (a zip bomb). Each
    member's ``.npy`` header states its shape and type."""
    from ..runtime.memory import available_bytes

    fmt = np.lib.format
    total = 0
    for name in z.files:
        with z.zip.open(name + ".npy") as fh:
            version = fmt.read_magic(fh)
            read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, _, dtype = read(fh)
        total += int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    have = available_bytes()
    if total > have // 4:
        raise PatternFileError(
            f"{path}: its arrays declare {total / 2**30:,.1f} GiB, more than this machine can "
            f"check ({have / 2**30:.1f} GiB available)"
        )


def _load_npz(path: Path, box: tuple[float, float, float, float] | None) -> Pattern:
    try:
        with np.load(path, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise PatternFileError(f"{path}: a .npy array, not a pattern .npz archive")
            _check_npz_sizes(path, z)
            xy = _real(path, z, "xy")
            dots = None
            if "shape" in z:
                name = str(z["shape"])
                if name not in KINDS or KINDS[name].round:
                    raise PatternFileError(
                        f"{path}: shape = {name[:40]!r} is not a shaped dot's kind "
                        f"({', '.join(k for k, v in KINDS.items() if not v.round)})"
                    )
                try:
                    spec = json.loads(str(z["shape_spec"])) if "shape_spec" in z else None
                    kind = kind_of(name, spec)
                except (ValueError, RecursionError) as e:
                    raise PatternFileError(f"{path}: shape_spec: {one_line(e)}") from None
                size, angle = _real(path, z, "size"), _real(path, z, "angle_deg")
                k = len(kind.params)
                if size.shape not in ((k,), (len(xy), k)) or angle.shape != (len(xy),):
                    raise PatternFileError(
                        f"{path}: size must be [{k}] or [{len(xy)}, {k}] and angle_deg "
                        f"[{len(xy)}], got {size.shape} and {angle.shape}"
                    )
                dots = file_footprints(path, kind, np.broadcast_to(size, (len(xy), k)), angle)
                diameter = dots.diameter
            else:
                diameter = _real(path, z, "diameter")
            file_box = _real(path, z, "box")
            meta = json.loads(str(z["meta"])) if "meta" in z else {}
            if not isinstance(meta, dict):
                raise PatternFileError(f"{path}: meta must be a JSON object")
            outline = None
            if "outline_wkb" in z:
                margin = _real(path, z, "edge_margin")
                if margin.shape != () or not (np.isfinite(margin) and 0 <= margin < 100):
                    raise PatternFileError(f"{path}: edge_margin must be one number in 0..100 mm")
                wkb = np.asarray(z["outline_wkb"])
                if wkb.dtype != np.uint8 or wkb.ndim != 1:
                    raise PatternFileError(f"{path}: outline_wkb must be a 1-D uint8 array")
                geom = orient_all(shapely.from_wkb(wkb.tobytes()))
                caps = _caps(path, z) if "caps" in z else None
                rings = _rings(path, z, caps) if "cap_rings" in z else None
                outline = Domain(geom, float(margin), False, str(path), caps=caps, cap_rings=rings)
    except KeyError as e:
        raise PatternFileError(f"{path}: missing array {e} in pattern .npz") from None
    except (
        OSError,
        ValueError,
        TypeError,
        EOFError,
        zipfile.BadZipFile,
        json.JSONDecodeError,
        shapely.errors.ShapelyError,
    ) as e:
        raise PatternFileError(f"{path}: not a readable pattern .npz ({one_line(e)})") from None
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) == 0:
        raise PatternFileError(f"{path}: xy must have shape [n, 2] with n > 0, got {xy.shape}")
    if file_box.shape != (4,):
        raise PatternFileError(f"{path}: box must be 4 numbers, got shape {file_box.shape}")
    if diameter.ndim > 1 or (diameter.ndim == 1 and diameter.shape != (len(xy),)):
        raise PatternFileError(
            f"{path}: diameter must be one number or one per dot ({len(xy)}), "
            f"got shape {diameter.shape}"
        )
    the_box = box or tuple(file_box.tolist())
    p = _validated(path, xy, np.broadcast_to(diameter, (len(xy),)), the_box, meta, dots)
    return p if outline is None else replace(p, outline=outline)


def _rings(path: Path, z, caps: np.ndarray | None) -> np.ndarray:
    """The ``cap_rings`` array of the archive, checked against its caps."""
    rings = np.asarray(z["cap_rings"])
    if caps is None:
        raise PatternFileError(f"{path}: cap_rings without caps")
    problem = rings_problem(rings, caps)
    if problem is not None:
        raise PatternFileError(f"{path}: {problem}")
    return rings.astype(np.float64).reshape(-1, 2)


def _caps(path: Path, z) -> np.ndarray:
    """The ``caps`` array of the archive, checked."""
    caps = np.asarray(z["caps"])
    problem = caps_problem(caps)
    if problem is not None:
        raise PatternFileError(f"{path}: {problem}")
    return caps.astype(np.float64)


def _real(path: Path, z, name: str) -> np.ndarray:
    """Array ``name`` of the archive as float64, refusing non-numeric or complex ones."""
    a = np.asarray(z[name])
    if a.dtype.kind not in "biuf":
        raise PatternFileError(f"{path}: {name} must hold real numbers, got dtype {a.dtype}")
    return a.astype(np.float64)


def _validated(path, xy, diam, box, meta, dots: Footprints | None = None) -> Pattern:
    validate_dots(path, xy, diam, box)
    if box is None:
        lo = (xy - diam[:, None] / 2).min(axis=0)
        hi = (xy + diam[:, None] / 2).max(axis=0)
        box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    if not (box[2] > box[0] and box[3] > box[1]):
        raise PatternFileError(f"{path}: empty panel box {box}")
    return Pattern(xy=xy, diameter=diam, box=box, meta={**meta, "source": str(path)}, dots=dots)
