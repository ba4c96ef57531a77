"""Previews for people: an SVG and a PNG of the pattern.

PNG: left, the whole panel as a coverage map (share of area covered by dots, binned to at
most ~400 px a side); right, a true-scale zoom tile (1 mm², dots drawn as circles,
shaped dots as their outlines).
SVG: every dot as a circle when there are at most 200k dots, else the zoom tile only
(a browser cannot draw millions of SVG circles), always with the panel outline. Caps
over LEDs (:mod:`optdot.geometry.caps`) are drawn as the solid discs they are, graded
caps as their rings.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optdot.io.atomic import atomic_path, expect_tail
from optdot.pattern import Pattern, caps_of, coverage_image

SVG_MAX_DOTS = 200_000
#: A PNG file's last chunk (IEND with its CRC).
PNG_END = b"IEND\xaeB`\x82"
TILE_MM = 1.0


def zoom_tile(pattern: Pattern, size: float = TILE_MM) -> tuple[float, float, float, float]:
    """A ``size`` mm square window around the panel centre, clipped to the panel."""
    x0, y0, x1, y1 = pattern.box
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    h = 0.5 * min(size, x1 - x0, y1 - y0)
    return cx - h, cy - h, cx + h, cy + h


def write_png(pattern: Pattern, path: str | Path, opts=None, dpi: int = 110) -> str:
    """Write the PNG preview atomically (``opts``: the export's options, none apply).

    Returns:
        What it shows, in words.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection

    img, ext = coverage_image(pattern)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.6, 1]})
    im = a.imshow(img, origin="lower", extent=ext, cmap="viridis", interpolation="nearest")
    a.set_title(f"{pattern.n:,} dots: coverage")
    a.set_xlabel("x (mm)")
    a.set_ylabel("y (mm)")
    fig.colorbar(im, ax=a, label="fill fraction")
    for ring in pattern.outline_rings():
        closed = np.vstack([ring, ring[:1]])
        a.plot(closed[:, 0], closed[:, 1], color="white", lw=0.8)
    tx0, ty0, tx1, ty1 = zoom_tile(pattern)
    a.add_patch(plt.Rectangle((tx0, ty0), tx1 - tx0, ty1 - ty0, fill=False, ec="red"))
    sel = _in_window(pattern, (tx0, ty0, tx1, ty1))
    if pattern.dots is None:
        d = pattern.uniform_diameter or pattern.diameter[sel]
        b.add_collection(
            EllipseCollection(
                d, d, 0, units="xy", offsets=pattern.xy[sel], offset_transform=b.transData, fc="k"
            )
        )
    else:
        from matplotlib.collections import PolyCollection

        b.add_collection(PolyCollection(_outlines(pattern, sel), fc="k", lw=0))
    caps = _caps_near(pattern, (tx0, ty0, tx1, ty1))
    rings = _rings(pattern)
    if len(caps) and rings is None:
        d = caps[:, 2]
        b.add_collection(
            EllipseCollection(
                d, d, 0, units="xy", offsets=caps[:, :2], offset_transform=b.transData, fc="k"
            )
        )
    elif len(caps):  # graded: each ring an annulus (a disc from the centre)
        from matplotlib.collections import PatchCollection
        from matplotlib.patches import Wedge

        wedges = [
            Wedge((x, y), r_out, 0, 360, width=None if r_in == 0 else r_out - r_in)
            for x, y, _ in caps.tolist()
            for r_in, r_out in rings.tolist()
        ]
        b.add_collection(PatchCollection(wedges, fc="k", lw=0))
    b.set_xlim(tx0, tx1)
    b.set_ylim(ty0, ty1)
    b.set_aspect("equal")
    b.set_title(f"true-scale zoom ({tx1 - tx0:.2g} mm tile)")
    b.set_xlabel("x (mm)")
    b.set_ylabel("y (mm)")
    fig.tight_layout()
    with atomic_path(path, expect_tail(PNG_END, str(path))) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return f"PNG preview: coverage of {pattern.n:,} dots and a zoomed window"


def write_svg(pattern: Pattern, path: str | Path, opts=None) -> str | None:
    """Write the SVG preview atomically (units: mm, y up as in the pattern): every dot,
    or above :data:`SVG_MAX_DOTS` the densest window only (``opts``: the export's
    options, none apply).

    Returns:
        The window and the dots it shows, in words, when it is not every dot (None).
    """
    x0, y0, x1, y1 = pattern.box
    window = (x0, y0, x1, y1) if pattern.n <= SVG_MAX_DOTS else zoom_tile(pattern)
    wx0, wy0, wx1, wy1 = window
    sel = _in_window(pattern, window)
    u = pattern.uniform_diameter
    radius = pattern.radius[sel]
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>\n',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{wx1 - wx0:.6f}mm" '
        f'height="{wy1 - wy0:.6f}mm" '
        f'viewBox="{wx0:.6f} {-wy1:.6f} {wx1 - wx0:.6f} {wy1 - wy0:.6f}">\n',
        f"<title>{_shown(int(sel.sum()), pattern.n)}, diameter {_diameter(pattern)} mm</title>\n",
    ]
    for ring in pattern.outline_rings():
        d = " ".join(f"{x:.6f},{-y:.6f}" for x, y in ring.tolist())
        out.append(f'<polygon points="{d}" fill="none" stroke="red" stroke-width="0.01"/>\n')
    out.append('<g fill="black">\n')
    if pattern.dots is not None:
        for ring in _outlines(pattern, sel):
            d = " ".join(f"{x:.6f},{-y:.6f}" for x, y in ring.tolist())
            out.append(f'<polygon points="{d}"/>\n')
    elif u is not None:
        r = 0.5 * u
        out += [
            f'<circle cx="{x:.6f}" cy="{-y:.6f}" r="{r:.6f}"/>\n'
            for x, y in pattern.xy[sel].tolist()
        ]
    else:
        out += [
            f'<circle cx="{x:.6f}" cy="{-y:.6f}" r="{r:.6f}"/>\n'
            for (x, y), r in zip(pattern.xy[sel].tolist(), radius.tolist(), strict=True)
        ]
    rings = _rings(pattern)
    for x, y, d in _caps_near(pattern, window).tolist():
        if rings is None:
            out.append(f'<circle cx="{x:.6f}" cy="{-y:.6f}" r="{0.5 * d:.6f}" class="cap"/>\n')
            continue
        for r_in, r_out in rings.tolist():  # a ring: a circle stroked as wide as the ring
            if r_in == 0:
                out.append(f'<circle cx="{x:.6f}" cy="{-y:.6f}" r="{r_out:.6f}" class="cap"/>\n')
            else:
                out.append(
                    f'<circle cx="{x:.6f}" cy="{-y:.6f}" r="{0.5 * (r_in + r_out):.6f}" '
                    f'fill="none" stroke="black" stroke-width="{r_out - r_in:.6f}" '
                    'class="cap"/>\n'
                )
    out.append("</g>\n</svg>\n")
    with atomic_path(path, expect_tail(b"</svg>\n", str(path))) as tmp:
        tmp.write_text("".join(out), encoding="utf-8")
    shown = int(sel.sum())
    if shown == pattern.n:
        return None
    return (
        f"SVG preview of a {wx1 - wx0:.2f} x {wy1 - wy0:.2f} mm window at ({wx0:.2f}, "
        f"{wy0:.2f}) mm: {shown:,} of {pattern.n:,} dots"
    )


def _rings(pattern: Pattern) -> np.ndarray | None:
    """The graded caps' rings ``[k, 2]`` mm, or None for solid caps."""
    return None if pattern.outline is None else pattern.outline.cap_rings


def _caps_near(pattern: Pattern, w: tuple[float, float, float, float]) -> np.ndarray:
    """The caps (:func:`optdot.pattern.caps_of`) that reach into the window ``w``."""
    caps = caps_of(pattern)
    r = 0.5 * caps[:, 2]
    x, y = caps[:, 0], caps[:, 1]
    near = (x + r >= w[0]) & (x - r <= w[2]) & (y + r >= w[1]) & (y - r <= w[3])
    return caps[near]


#: How close a preview's polygon of a shaped dot stays to its footprint, mm.
PREVIEW_TOLERANCE = 2e-4


def _outlines(pattern: Pattern, sel: np.ndarray) -> list[np.ndarray]:
    """``[v, 2]`` polygons (mm, placed) of the shaped dots ``sel`` (a boolean mask)."""
    dots = pattern.dots
    return [dots.outline(int(k), PREVIEW_TOLERANCE) + pattern.xy[k] for k in np.flatnonzero(sel)]


def _shown(k: int, n: int) -> str:
    return f"{n} dots" if k == n else f"{k} of {n} dots (a window)"


def _diameter(pattern: Pattern) -> str:
    if pattern.dots is not None:
        size = " x ".join(f"{v:g}" for v in pattern.dots.size[0])
        return f"{pattern.kind.name} {size}"
    u = pattern.uniform_diameter
    if u is not None:
        return f"{u}"
    return f"{pattern.diameter.min()}..{pattern.diameter.max()}"


def _in_window(pattern: Pattern, w: tuple[float, float, float, float]) -> np.ndarray:
    xy = pattern.xy
    r = pattern.radius
    return (
        (xy[:, 0] > w[0] - r)
        & (xy[:, 0] < w[2] + r)
        & (xy[:, 1] > w[1] - r)
        & (xy[:, 1] < w[3] + r)
    )
