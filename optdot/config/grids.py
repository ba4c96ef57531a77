"""Density grids from files: CSV (row 0 = bottom) or ``.npy``, and their range checks."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import JobError, one_line
from ..files import input_problem
from ..geometry.density import HEX_PACKING_LIMIT


def load_grid(path: Path, what: str = "density grid") -> np.ndarray:
    """Read a fill-fraction grid from CSV (comma-separated, row 0 = bottom) or ``.npy``
    (``what`` names it in messages).

    Returns:
        ``[ny, nx]`` float64 (not yet range-checked; see :func:`validate_grid`).
    """
    binary = path.suffix.lower() == ".npy"  # sized from its header below
    problem = input_problem(path, 1 << 62 if binary else None)
    if problem is not None:
        raise JobError(f"{path}: {what} {problem}")
    if binary:
        return _load_npy(path, what)
    image = _image_kind(path)
    if image is not None:
        raise JobError(
            f"{path}: {what} is {image} image, not a grid: give it as a CSV of numbers "
            "(row 0 = bottom) or .npy"
            + (" (a map as an image: [density] image)" if what == "density grid" else "")
        )
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise JobError(f"{path}: cannot read {what} ({e})") from None
    rows: list[list[float]] = []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or all(not c.strip() for c in row):
            continue
        if row[0].lstrip().startswith("#"):
            continue
        try:
            rows.append([float(c) for c in row])
        except ValueError:
            bad = next(c for c in row if not _is_float(c))
            raise JobError(
                f"{path}: line {lineno}: {bad.strip()[:40]!r} is not a number{_hint(row, rows)}"
            ) from None
        if len(rows[-1]) != len(rows[0]):
            raise JobError(
                f"{path}: line {lineno}: wrong grid shape, {len(rows[-1])} columns where "
                f"line 1 has {len(rows[0])}"
            )
    if not rows:
        raise JobError(f"{path}: {what} is empty")
    return np.array(rows, dtype=np.float64)


#: The first bytes of the image formats a grid may be mistaken for.
IMAGE_SIGNATURES = {
    b"\x89PNG": "a PNG",
    b"II*\x00": "a TIFF",
    b"MM\x00*": "a TIFF",
    b"\xff\xd8\xff": "a JPEG",
    b"GIF8": "a GIF",
    b"BM": "a BMP",
}


def _image_kind(path: Path) -> str | None:
    """``"a PNG"`` (and the like) when ``path`` starts as an image does, else None."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return None
    return next((k for sig, k in IMAGE_SIGNATURES.items() if head.startswith(sig)), None)


def _load_npy(path: Path, what: str = "density grid") -> np.ndarray:
    """A 2-D real ``.npy`` grid; the header is checked against the file before any
    memory is taken (a header may claim any size)."""
    fmt = np.lib.format
    try:
        with open(path, "rb") as fh:
            if fh.read(4) == b"PK\x03\x04":
                raise JobError(f"{path}: is a .npz archive, not a .npy array (save with np.save)")
            fh.seek(0)
            try:
                version = fmt.read_magic(fh)
                if version == (1, 0):
                    shape, fortran, dtype = fmt.read_array_header_1_0(fh)
                else:
                    shape, fortran, dtype = fmt.read_array_header_2_0(fh)
            except Exception as e:  # noqa: BLE001 - numpy's header parser raises many kinds
                raise JobError(f"{path}: not a .npy array ({one_line(e)})") from None
            if len(shape) != 2 or 0 in shape:
                raise JobError(f"{path}: grid must be a non-empty 2-D array, got shape {shape}")
            if dtype.hasobject or dtype.kind not in "biuf":
                raise JobError(f"{path}: grid must hold real numbers, got dtype {dtype}")
            need = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
            have = path.stat().st_size - fh.tell()
            if need > have:
                raise JobError(
                    f"{path}: the header claims a {shape[0]} x {shape[1]} {dtype} array "
                    f"({need:,} bytes) but the file holds {have:,}: truncated or corrupt"
                )
        g = np.load(path, allow_pickle=False)
    except OSError as e:
        raise JobError(f"{path}: cannot read {what} ({e.strerror or e})") from None
    except ValueError as e:
        raise JobError(f"{path}: not a readable .npy array ({one_line(e)})") from None
    return np.asarray(g, dtype=np.float64)


def validate_grid(g: np.ndarray, where: str) -> None:
    """Refuse NaN, negative, at-or-above-packing-limit or all-zero fill fractions."""
    if not np.all(np.isfinite(g)):
        iy, ix = np.argwhere(~np.isfinite(g))[0]
        raise JobError(f"{where}: NaN or infinite fill fraction at row {iy}, column {ix}")
    if np.any(g < 0):
        iy, ix = np.argwhere(g < 0)[0]
        raise JobError(f"{where}: negative fill fraction {g[iy, ix]} at row {iy}, column {ix}")
    if np.any(g >= HEX_PACKING_LIMIT):
        iy, ix = np.argwhere(g >= HEX_PACKING_LIMIT)[0]
        percent = (
            " (the map looks like percent, 0-100: divide it by 100)"
            if g.max() <= 100 and g.max() > 1.0
            else ""
        )
        raise JobError(
            f"{where}: fill fraction {g[iy, ix]} at row {iy}, column {ix} is at or above the "
            f"hexagonal packing limit {HEX_PACKING_LIMIT:.4f}{percent}"
        )
    if not np.any(g > 0):
        raise JobError(f"{where}: the map is all zero, there is nothing to place")


def _hint(row: list[str], rows: list[list[float]]) -> str:
    """What a row that is not all numbers may be: another separator, or a header."""
    cell = ",".join(row)
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if sep in cell and all(_is_float(c) for c in cell.split(sep) if c.strip()):
            return f" (the values are separated by {name}: the grid must be comma-separated)"
    if not rows and row and not row[0].strip() and all(_is_float(c) for c in row[1:]):
        return (
            " (a header row over an index column, as pandas' to_csv writes: write the grid "
            "with index=False, header=False; the grid holds numbers only)"
        )
    if not rows and not any(_is_float(c) for c in row):
        return " (a header row? the grid holds numbers only; start a comment line with #)"
    return ""


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
