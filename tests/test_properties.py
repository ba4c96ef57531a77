"""Property-based hostile inputs: whatever the job, grid, outline or pattern
file holds, reading it ends in a value or in an :class:`~optdot.errors.OptdotError` (one
line and a documented exit code at the command line), never in another exception.

Derandomised, so CI runs the same few hundred examples per reader every time; a longer
random soak: ``OPTDOT_SOAK=5000 pytest tests/test_properties.py``.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import tempfile
import zipfile
from pathlib import Path

import ezdxf
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from optdot.config.grids import load_grid, validate_grid
from optdot.config.schema import SCHEMA, load_job
from optdot.config.writer import toml_value
from optdot.errors import OptdotError
from optdot.exporters import write
from optdot.exporters.readback import read_any
from optdot.geometry.limits import DIAMETER_RANGE_MM, MAX_EXTENT_MM
from optdot.geometry.outline_io import load_outline
from optdot.orchestration.pipeline import _check_room, qa

SOAK = int(os.environ.get("OPTDOT_SOAK", "0"))
SETTINGS = settings(
    max_examples=SOAK or 200,
    deadline=None,
    derandomize=not SOAK,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
WORK = Path(tempfile.mkdtemp(prefix="optdot-props-"))


def outcome(fn, *args, valid: bool | None = None):
    """Call ``fn``; an OptdotError (one line) is an answer, anything else fails the test.

    ``valid`` is what the input is by construction: True (good) — a refusal fails the test,
    so refusing everything cannot pass these suites; False (bad) — a load fails it, so
    accepting everything cannot either; None (not decided by the strategy) — either."""
    try:
        result = fn(*args)
    except OptdotError as e:
        text = str(e)
        assert text and "\n" not in text, repr(text)
        assert valid is not True, f"a valid input was refused: {text}"
        return None
    assert valid is not False, f"an invalid input was accepted: {args!r:.300}"
    return result


NUMBER = re.compile(r"\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*")


def _numbers(rows) -> list[list[float]] | None:
    """The rows as numbers when every cell is a plain finite number (else None)."""
    out = []
    for r in rows:
        if not r or not all(NUMBER.fullmatch(c) for c in r):
            return None
        vals = [float(c) for c in r]
        if not all(math.isfinite(v) for v in vals):
            return None
        out.append(vals)
    return out


def _valid_fills(values) -> bool:
    a = np.asarray(values, dtype=np.float64)
    return bool(
        a.size and np.isfinite(a).all() and (a >= 0).all() and (a < 0.9069).all() and (a > 0).any()
    )


# --- values -------------------------------------------------------------------------------

floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e3, 1e3),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.046, 0.5, 0.9, 1.0, 3.0]),
)
ints = st.one_of(st.integers(-(2**70), 2**70), st.integers(-5, 2000))
text_values = st.one_of(
    st.text(max_size=20),
    st.sampled_from(["optdot", "md", "paper", "density.csv", "o.dxf", "o.wkt", "missing.csv", ""]),
)
toml_values = st.one_of(floats, ints, st.booleans(), text_values, st.lists(text_values, max_size=3))


@st.composite
def job_texts(draw) -> str:
    """A TOML job: mostly the schema's keys (some required ones dropped), some strangers,
    values of any type and range."""
    base = {
        "domain": {"width": 3.0, "height": 2.0},
        "density": {"grid": "density.csv"},
        "dots": {"diameter": 0.046},
    }
    for sec in draw(st.lists(st.sampled_from([s for s in SCHEMA if s] + ["bogus"]), max_size=4)):
        keys = list(SCHEMA.get(sec, {"x": ()})) + ["unknown_key"]
        for key in draw(st.lists(st.sampled_from(keys), max_size=4)):
            base.setdefault(sec, {})[key] = draw(toml_values)
    for sec in draw(st.lists(st.sampled_from(list(base)), max_size=2)):
        if base[sec]:
            base[sec].pop(draw(st.sampled_from(sorted(base[sec]))))
    lines = []
    if draw(st.booleans()):
        lines.append(f"name = {toml_value(draw(toml_values))}")
    for sec, kv in base.items():
        lines.append(f"[{sec}]")
        lines += [f"{k} = {toml_value(v)}" for k, v in kv.items()]
    text = "\n".join(lines) + "\n"
    if draw(st.integers(0, 9)) == 0:  # sometimes plain garbage, or a cut
        text = text[: draw(st.integers(0, len(text)))] + draw(st.text(max_size=10))
    return text


def _job_dir() -> Path:
    d = WORK / "job"
    d.mkdir(exist_ok=True)
    np.savetxt(d / "density.csv", np.full((4, 6), 0.3), delimiter=",")
    (d / "o.wkt").write_text("POLYGON ((0 0, 3 0, 3 2, 0 2, 0 0), (1 1, 1.5 1, 1.5 1.5, 1 1))")
    doc = ezdxf.new(units=4)
    doc.modelspace().add_lwpolyline([(0, 0), (3, 0), (3, 2), (0, 2)], close=True)
    doc.modelspace().add_circle((1.5, 1.0), 0.3)
    doc.saveas(d / "o.dxf")
    return d


@pytest.mark.slow
@SETTINGS
@given(job_texts())
def test_any_job_file_loads_or_is_refused_in_one_line(text):
    d = _job_dir() if not (WORK / "job").exists() else WORK / "job"
    (d / "job.toml").write_text(text, encoding="utf-8", errors="surrogatepass")

    def load():
        job = load_job(d / "job.toml")
        _check_room(job, job.n_dots, "job")  # what generate checks before any work
        return job

    outcome(load)


# --- density grids ------------------------------------------------------------------------

csv_cells = st.one_of(
    floats.map(repr),
    st.sampled_from(["", " ", "#", "nan", "inf", "-1", "0", "0.5", "1e400", "a", "\ufeff0.1"]),
    st.text(max_size=5),
)


@SETTINGS
@given(st.lists(st.lists(csv_cells, min_size=0, max_size=5), max_size=6))
@example([["0.1", "0.2", "0"], ["0.3", "0.45", " 1e-1"]])  # a good map is read as it is
@example([["0.1", "0.2"], ["0.3", "-0.1"]])  # numbers, one negative: refused
@example([["0.1", "0.2"], ["0.3"]])  # numbers, ragged: refused
def test_any_grid_csv_loads_or_is_refused(rows):
    path = WORK / "grid.csv"
    path.write_text("\n".join(",".join(r) for r in rows), errors="surrogatepass")

    def load():
        g = load_grid(path)
        validate_grid(g, str(path))
        return g

    nums = _numbers(rows)
    valid = bool(nums) and len({len(r) for r in nums}) == 1 and _valid_fills(nums)
    if nums and not valid:  # plain numbers, but ragged or not fills: refused
        valid = False
    elif not valid:
        valid = None  # blank cells, comments, text: decided by the reader's rules
    g = outcome(load, valid=valid)
    if valid:
        np.testing.assert_array_equal(g, np.array(nums))


npy_dtypes = st.one_of(
    hnp.floating_dtypes(),
    hnp.integer_dtypes(),
    hnp.boolean_dtypes(),
    hnp.complex_number_dtypes(),
    hnp.unicode_string_dtypes(max_len=3),
    hnp.datetime64_dtypes(),
)


@pytest.mark.slow
@SETTINGS
@given(
    hnp.arrays(npy_dtypes, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5)),
    st.integers(0, 4),
    st.integers(0, 400),
)
@example(np.full((2, 3), 0.2), 0, 0)
@example(np.array([[0, 1], [2, 0]], dtype=np.uint8) * 0, 0, 0)  # all zero: refused
def test_any_npy_grid_loads_or_is_refused(arr, damage, cut):
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    data = buf.getvalue()
    if damage == 1:
        data = data[: min(cut, len(data))]
    elif damage == 2 and len(data) > 20:
        data = data[:10] + bytes([cut % 256]) + data[11:]
    path = WORK / "grid.npy"
    path.write_bytes(data)

    def load():
        g = load_grid(path)
        validate_grid(g, str(path))
        return g

    valid = (
        damage == 0
        and arr.ndim == 2
        and 0 not in arr.shape
        and arr.dtype.kind in "biuf"
        and _valid_fills(arr.astype(np.float64))
    )
    outcome(load, valid=True if valid else (False if damage == 0 else None))


# --- outlines -----------------------------------------------------------------------------

coords = st.floats(-50, 50, allow_nan=False) | st.sampled_from([0.0, 1.0, 1e9, float("nan")])
rings = st.lists(st.tuples(coords, coords), min_size=0, max_size=7)


def wkt_ring(r) -> str:
    return "(" + ", ".join(f"{x!r} {y!r}" for x, y in r) + ")"


@pytest.mark.slow
@SETTINGS
@given(
    st.sampled_from(["POLYGON", "MULTIPOLYGON", "LINESTRING", "POINT", "GEOMETRYCOLLECTION", "X"]),
    st.lists(rings, min_size=0, max_size=3),
    st.text(max_size=5),
    st.booleans(),
)
@example("POLYGON", [[(0.0, 0.0), (3.0, 0.0), (3.0, 2.0), (0.0, 2.0)]], "", True)
def test_any_wkt_outline_loads_or_is_refused(kind, rs, junk, close):
    if close:  # as a CAD program writes them: each ring ends where it starts
        rs = [[*r, r[0]] for r in rs if r]
    body = "(" + ", ".join(wkt_ring(r) for r in rs) + ")" if rs else "EMPTY"
    if kind == "MULTIPOLYGON" and rs:
        body = "(" + body + ")"
    path = WORK / "o.wkt"
    path.write_text(f"{kind} {body}{junk}", errors="surrogatepass")
    valid = False if kind in ("LINESTRING", "POINT", "X") else None  # never a panel
    if (
        kind == "POLYGON"
        and rs
        and not junk.strip()
        and all(
            len(r) >= 4 and r[0] == r[-1] and all(math.isfinite(v) for xy in r for v in xy)
            for r in rs
        )
    ):
        poly = shapely.Polygon(rs[0], rs[1:])
        valid = bool(poly.is_valid and poly.area > 0)
    outcome(load_outline, path, valid=valid)


json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-5, 5), coords, st.text(max_size=8))
json_any = st.recursive(
    json_leaf,
    lambda kids: st.one_of(
        st.lists(kids, max_size=4), st.dictionaries(st.text(max_size=6), kids, max_size=4)
    ),
    max_leaves=12,
)
geojson_like = st.fixed_dictionaries(
    {
        "type": st.sampled_from(
            ["Polygon", "MultiPolygon", "Feature", "FeatureCollection", "Point", "x"]
        ),
        "coordinates": st.one_of(st.lists(rings, max_size=2), json_any),
    },
    optional={"geometry": json_any, "features": st.lists(json_any, max_size=3)},
)


@pytest.mark.slow
@SETTINGS
@given(st.one_of(geojson_like, json_any))
def test_any_geojson_outline_loads_or_is_refused(data):
    path = WORK / "o.geojson"
    path.write_text(json.dumps(data))
    outcome(load_outline, path)


dxf_num = st.floats(-20, 20, allow_nan=False) | st.sampled_from([0.0, -1.0, 1e-12, 1e12])
entity = st.one_of(
    st.tuples(st.just("circle"), dxf_num, dxf_num, dxf_num),
    st.tuples(st.just("arc"), dxf_num, dxf_num, dxf_num, dxf_num, dxf_num),
    st.tuples(st.just("line"), dxf_num, dxf_num, dxf_num, dxf_num),
    st.tuples(
        st.just("lwpolyline"),
        st.lists(st.tuples(dxf_num, dxf_num, dxf_num), max_size=5),
        st.booleans(),
    ),
    st.tuples(st.just("ellipse"), dxf_num, dxf_num, dxf_num, st.floats(1e-6, 1.0), dxf_num),
)


def _dxf_bytes(entities, extrusion_flip: bool) -> bytes:
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    attribs = {"extrusion": (0, 0, -1)} if extrusion_flip else {}
    for e in entities:
        kind = e[0]
        if kind == "circle":
            msp.add_circle((e[1], e[2]), e[3], dxfattribs=attribs)
        elif kind == "arc":
            msp.add_arc((e[1], e[2]), e[3], e[4], e[5], dxfattribs=attribs)
        elif kind == "line":
            msp.add_line((e[1], e[2]), (e[3], e[4]))
        elif kind == "lwpolyline":
            msp.add_lwpolyline(e[1], format="xyb", close=e[2], dxfattribs=attribs)
        else:
            if e[3] == 0 and e[1] == 0:
                continue
            msp.add_ellipse((e[1], e[2]), major_axis=(e[3] or 1.0, e[5]), ratio=e[4])
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode()


@pytest.mark.slow  # over 1.5 s
@SETTINGS
@given(st.lists(entity, max_size=5), st.booleans(), st.integers(0, 3), st.integers(0, 10**6))
def test_any_dxf_outline_loads_or_is_refused(entities, flip, damage, cut):
    try:
        data = _dxf_bytes(entities, flip)
    except (ValueError, ezdxf.DXFError, ZeroDivisionError):
        assume(False)  # ezdxf refused to draw it: not a file a user can have
    if damage == 1:
        data = data[: cut % (len(data) + 1)]
    path = WORK / "o.dxf"
    path.write_bytes(data)
    outcome(load_outline, path, 1e-3)


# --- pattern files ------------------------------------------------------------------------


@SETTINGS
@given(
    st.sampled_from(["x_mm,y_mm,diameter_mm", "x,y", "", "\ufeffx_mm,y_mm,diameter_mm"]),
    st.lists(st.lists(csv_cells, min_size=0, max_size=4), max_size=6),
)
@example("x_mm,y_mm,diameter_mm", [["1.0", "1.0", "0.046"], ["1.2", "1.0", "0.046"]])
def test_any_pattern_csv_reads_or_is_refused(header, rows):
    path = WORK / "p.csv"
    path.write_text(header + "\n" + "\n".join(",".join(r) for r in rows), errors="surrogatepass")
    nums = _numbers([r for r in rows if r])
    valid = None
    if header.lstrip("\ufeff") == "x_mm,y_mm,diameter_mm" and nums:
        a = np.array(nums) if all(len(r) == 3 for r in nums) else None
        lo, hi = DIAMETER_RANGE_MM
        valid = a is not None and bool((a[:, 2] >= lo).all() and (a[:, 2] <= hi).all())
        valid = valid and float(np.ptp(a[:, :2], axis=0).max()) <= MAX_EXTENT_MM
    p = outcome(read_any, path, valid=valid)
    if p is not None:
        outcome(qa, p, valid=valid)


small_arrays = hnp.arrays(
    st.one_of(hnp.floating_dtypes(), hnp.integer_dtypes(), hnp.unicode_string_dtypes(max_len=4)),
    hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4),
)


@pytest.mark.slow
@SETTINGS
@given(
    st.dictionaries(
        st.sampled_from(["xy", "diameter", "box", "meta", "outline_wkb", "edge_margin", "other"]),
        small_arrays,
        max_size=7,
    ),
    st.booleans(),
)
@example({}, True)
@example({"other": np.zeros(2)}, True)
def test_any_pattern_npz_reads_or_is_refused(arrays, good_core):
    valid = good_core and set(arrays) <= {"other"}
    if not good_core and "xy" not in arrays:
        valid = False  # no dots at all: refused
    elif not valid:
        valid = None
    if good_core:  # a plausible core so the readers get past the first key
        arrays.setdefault("xy", np.array([[0.5, 0.5], [1.0, 1.0], [1.5, 0.5]]))
        arrays.setdefault("diameter", np.array(0.046))
        arrays.setdefault("box", np.array([0.0, 0.0, 2.0, 2.0]))
    path = WORK / "p.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=False)
            zf.writestr(f"{name}.npy", buf.getvalue())
    p = outcome(read_any, path, valid=valid)
    if p is not None:
        outcome(qa, p, valid=valid)


@pytest.fixture(scope="module")
def masks(tiny_pattern):
    out = {}
    for fmt in ("gds", "oas", "dxf"):
        path = WORK / f"good.{fmt}"
        write(tiny_pattern, fmt, path)
        out[fmt] = path.read_bytes()
    return out


@settings(
    SETTINGS,
    suppress_health_check=[*SETTINGS.suppress_health_check, HealthCheck.function_scoped_fixture],
)
@given(
    st.sampled_from(["gds", "oas", "dxf"]),
    st.lists(st.tuples(st.integers(0, 10**7), st.integers(0, 255)), max_size=4),
    st.one_of(st.none(), st.integers(0, 10**7)),
)
@example(fmt="gds", flips=[], cut=None)
@example(fmt="oas", flips=[], cut=None)
@example(fmt="dxf", flips=[], cut=None)
@pytest.mark.slow
def test_any_damaged_mask_reads_or_is_refused(masks, fmt, flips, cut):
    data = bytearray(masks[fmt])
    for pos, val in flips:
        data[pos % len(data)] = val
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    path = WORK / f"m.{fmt}"
    path.write_bytes(bytes(data))
    intact = bytes(data) == masks[fmt]
    p = outcome(read_any, path, valid=True if intact else None)
    if intact:
        assert p.n == 869
