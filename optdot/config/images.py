"""Density maps from images: 8/16-bit grayscale PNG or TIFF, or float32 TIFF (Pillow).

What optical design tools hand over is an image of the fill map at 0.1-0.5 mm per pixel.
The image spans the panel's box (pixels need not divide it evenly, and may be smaller than
a dot). **Images are top-down**: row 0 of the file is the panel's top edge (y = height),
as every image viewer shows it; the grid returned here is flipped to the grids' convention
(row 0 = bottom, y = 0).

Pixel values become fill fractions linearly:

- integer images (8-bit ``L``, 16-bit ``I;16``): the format's full range (0-255, 0-65535),
  or ``value_range = [a, b]`` when given, maps to ``fill_range = [lo, hi]`` (required:
  an integer carries no unit; ``lo > hi`` inverts, for maps where white means no dots);
- float images (``F``): the values are fill fractions, unless a ``value_range`` (and
  ``fill_range``, default ``[0, 1]``) maps them.

A value outside ``value_range`` is refused, not clipped: the map would silently differ
from the designer's. Colour, palette and alpha images are refused (say which channel
is the map by converting to grayscale first).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import JobError, ResourceError, one_line
from ..files import input_problem
from ..runtime.memory import available_bytes

#: Image suffixes read as density maps.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff")
#: Largest image accepted, pixels (a 1.2 m panel at 0.05 mm is 3.3·10⁸).
MAX_PIXELS = 400_000_000
#: Full range of each integer mode, the values ``fill_range`` maps from by default.
_FULL = {
    "L": (0.0, 255.0),
    "I;16": (0.0, 65535.0),
    "I;16L": (0.0, 65535.0),
    "I;16B": (0.0, 65535.0),
    "1": (0.0, 1.0),
}


#: Bytes per pixel while a map is read: the pixels, float64 values and fills, masks.
BYTES_PER_PIXEL = 40


def _upright(im, path: Path):
    """The image as it is meant to be seen: the EXIF orientation of a PNG applied (an
    editor may store the pixels turned and say so in the tag).

    Pillow applies a TIFF's orientation tag itself while decoding, rightly for the
    mirrored and half-turned ones (2-4) but not for those turned by a quarter (5-8: the
    pixels come out scrambled, Pillow 13), so those are refused rather than read wrong."""
    from PIL import ImageOps

    if im.format == "TIFF":
        tag = getattr(im, "tag_v2", {}).get(0x0112, 1)
        if tag in (5, 6, 7, 8):
            raise JobError(
                f"{path}: TIFF orientation tag {tag} (turned by 90 degrees) is not read "
                "reliably; save the map upright (orientation 1) or as PNG"
            )
        return im
    return ImageOps.exif_transpose(im)


def load_image(
    path: Path,
    fill_range: tuple[float, float] | None = None,
    value_range: tuple[float, float] | None = None,
) -> np.ndarray:
    """Read an image density map as fill fractions.

    Args:
        path: PNG or TIFF file.
        fill_range: ``(lo, hi)`` fill fractions the value range maps to.
        value_range: ``(a, b)`` pixel values mapped to ``lo`` and ``hi`` (default: the
            integer format's full range; none for float images).

    Returns:
        ``[ny, nx]`` float64 fill fractions, row 0 = the panel's bottom edge (not yet
        range-checked: see :func:`optdot.config.grids.validate_grid`).

    Raises:
        JobError: unreadable file, unsupported mode, too large, or values outside
            ``value_range``; one line naming the file.
    """
    from PIL import Image

    problem = input_problem(path, 1 << 62)  # sized from its pixel count below
    if problem is not None:
        raise JobError(f"{path}: density image {problem}")
    Image.MAX_IMAGE_PIXELS = MAX_PIXELS
    try:
        with Image.open(path) as im:
            mode = im.mode
            w, h = im.size
            if w * h > MAX_PIXELS:
                raise JobError(f"{path}: {w} x {h} pixels is over the {MAX_PIXELS:,}-pixel limit")
            if mode not in _FULL and mode not in ("F", "I"):
                raise JobError(
                    f"{path}: image mode {mode!r} is not a grayscale map (use 8/16-bit "
                    "grayscale or float32; convert colour images to grayscale first)"
                )
            if getattr(im, "n_frames", 1) > 1:
                raise JobError(f"{path}: holds {im.n_frames} images; give one page")
            need = w * h * BYTES_PER_PIXEL
            have = available_bytes()
            if need > 0.8 * have:
                raise ResourceError(
                    f"{path}: {w} x {h} pixels need about {need / 2**30:.1f} GiB to read, "
                    f"{have / 2**30:.1f} GiB is available; resample the map (a cell of "
                    "1 mm is finer than any backlight needs)"
                )
            raw = np.asarray(_upright(im, path))
    except JobError:
        raise
    except (OSError, ValueError, Image.DecompressionBombError) as e:
        raise JobError(f"{path}: not a readable PNG/TIFF image ({one_line(e)})") from None
    if raw.ndim != 2 or 0 in raw.shape:
        raise JobError(f"{path}: expected one grayscale channel, got shape {raw.shape}")
    values = raw.astype(np.float64)
    if value_range is None and mode == "F":
        if fill_range is not None:
            value_range = (0.0, 1.0)
        else:
            return np.ascontiguousarray(values[::-1])
    if value_range is None:
        if mode == "I":
            raise JobError(
                f"{path}: 32-bit integer pixels: give density.value_range (which values "
                "are the fill range's ends)"
            )
        value_range = _FULL[mode]
    if fill_range is None:
        raise JobError(
            f"{path}: integer pixels carry no unit: give density.fill_range = [lo, hi], the "
            "fill fractions the darkest and brightest values stand for"
        )
    a, b = value_range
    lo, hi = fill_range
    finite = np.isfinite(values)
    outside = finite & ((values < min(a, b)) | (values > max(a, b)))
    if outside.any():
        iy, ix = np.argwhere(outside)[0]
        raise JobError(
            f"{path}: pixel value {values[iy, ix]:g} at row {iy}, column {ix} is outside "
            f"density.value_range [{a:g}, {b:g}]"
        )
    fill = lo + (values - a) * ((hi - lo) / (b - a))
    return np.ascontiguousarray(fill[::-1])


def check_ranges(fill_range, value_range, where: str) -> None:
    """Refuse ``fill_range`` / ``value_range`` that are not two distinct finite numbers
    (fills within [0, 1])."""
    for name, r in (("fill_range", fill_range), ("value_range", value_range)):
        if r is None:
            continue
        ok = (
            isinstance(r, list | tuple)
            and len(r) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in r)
            and all(np.isfinite(r))
            and r[0] != r[1]
        )
        if not ok:
            raise JobError(f"{where}: density.{name} = {r!r} must be two different numbers")
        if name == "fill_range" and not all(0.0 <= v <= 1.0 for v in r):
            raise JobError(f"{where}: density.fill_range = {r!r} must lie within [0, 1]")
