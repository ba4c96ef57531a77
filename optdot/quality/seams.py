"""Seam metrics of a tiled pattern: are the tile borders different from the tiles' insides?

Every dot is put in the *band* (within ``width`` of an inner tile border) or the
*interior* of the tile its centre lies in. Per tile and class this measures the share of
dots in a close pair, the mean |ψ6|, the coverage error (dot area over the map's integral
over the class's region: a tile minus a rectangle) and the normalised nearest-neighbour
distance. A seam nobody can find is a band whose numbers equal the interior's within the
spread across tiles: the check is ``|band - interior| <= 2 sqrt(sd_band² + sd_interior²)``,
the sds taken over the per-tile values of each class (a band holds a few thousand dots per
tile, an interior tens of thousands, so each has its own noise); the verdict is reported
per measure.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geometry.density import DensityMap

#: Width of the band along each inner tile border, mm.
BAND_MM = 0.5
#: Tiles whose class holds fewer dots are left out of the spread.
MIN_DOTS = 200


def seam_sums(
    xy: np.ndarray,
    areas: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    close_flag: np.ndarray,
    psi_abs: np.ndarray,
    nn_norm: np.ndarray | None,
    width: float = BAND_MM,
) -> dict[str, dict[str, np.ndarray]]:
    """Per-tile sums of some dots: ``{"band" | "interior": {"count", "close", "psi",
    "area"[, "nn", "nn_count"]: [tiles]}}``. Sums over the parts of a pattern add up to
    the whole pattern's (:func:`seam_finish` judges them).

    Args:
        xy: ``[n, 2]`` centres, mm. areas: ``[n]`` dot areas, mm².
        xs, ys: tile edges, mm (``[nx + 1]``, ``[ny + 1]``).
        close_flag: ``[n]`` bool, the dot is in a pair closer than the close distance.
        psi_abs: ``[n]`` |ψ6|.
        nn_norm: ``[n]`` nearest-neighbour distance over the local hexagonal spacing
            (NaN where the map gives no spacing: those dots are left out of its mean).
        width: band width, mm.
    """
    xs = np.asarray(xs, float)
    ys = np.asarray(ys, float)
    nx, ny = len(xs) - 1, len(ys) - 1
    ti = np.clip(np.searchsorted(xs, xy[:, 0], "right") - 1, 0, nx - 1)
    tj = np.clip(np.searchsorted(ys, xy[:, 1], "right") - 1, 0, ny - 1)
    dist = np.full(len(xy), np.inf)
    if nx > 1:
        dist = np.minimum(dist, np.abs(xy[:, 0, None] - xs[None, 1:-1]).min(axis=1))
    if ny > 1:
        dist = np.minimum(dist, np.abs(xy[:, 1, None] - ys[None, 1:-1]).min(axis=1))
    band = dist < width
    tile = tj * nx + ti
    k = nx * ny
    per: dict[str, dict[str, np.ndarray]] = {}
    for name, sel in (("band", band), ("interior", ~band)):
        cnt = np.bincount(tile[sel], minlength=k).astype(float)
        per[name] = {
            "count": cnt,
            "close": np.bincount(tile[sel], close_flag[sel].astype(float), minlength=k),
            "psi": np.bincount(tile[sel], psi_abs[sel], minlength=k),
            "area": np.bincount(tile[sel], areas[sel], minlength=k),
        }
        if nn_norm is not None:
            ok = sel & ~np.isnan(nn_norm)
            per[name]["nn"] = np.bincount(tile[ok], nn_norm[ok], minlength=k)
            per[name]["nn_count"] = np.bincount(tile[ok], minlength=k).astype(float)
    return per


def seam_finish(
    per: dict[str, dict[str, np.ndarray]],
    xs: np.ndarray,
    ys: np.ndarray,
    density: DensityMap | None,
    width: float = BAND_MM,
) -> dict[str, Any]:
    """Band-against-interior numbers of a tiled pattern from its summed
    :func:`seam_sums` (``density``: the map, None for no coverage numbers).

    Returns:
        ``{"band_mm", "tiles", "band_dots", "interior_dots", "measures": {name: {"band",
        "interior", "band_sd", "interior_sd", "passed"}}, "passed"}``; empty when there is
        one tile.
    """
    xs = np.asarray(xs, float)
    ys = np.asarray(ys, float)
    nx, ny = len(xs) - 1, len(ys) - 1
    k = nx * ny
    n_band = int(per["band"]["count"].sum())
    n_int = int(per["interior"]["count"].sum())
    if k < 2 or n_band + n_int == 0:
        return {}
    if density is not None:
        whole = np.zeros(k)
        inner = np.zeros(k)
        for j in range(ny):
            for i in range(nx):
                x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
                whole[j * nx + i] = density.integral(x0, y0, x1, y1)
                inner[j * nx + i] = density.integral(
                    x0 + (width if i > 0 else 0),
                    y0 + (width if j > 0 else 0),
                    x1 - (width if i < nx - 1 else 0),
                    y1 - (width if j < ny - 1 else 0),
                )
        per["band"]["target"] = whole - inner
        per["interior"]["target"] = inner
    measures: dict[str, dict[str, Any]] = {}

    def ratio(name: str, num: str, den: str, minus: float = 0.0) -> None:
        out: dict[str, Any] = {}
        for cls in ("band", "interior"):
            p = per[cls]
            out[cls] = float(p[num].sum() / max(p[den].sum(), 1e-300) - minus)
        for cls in ("band", "interior"):
            p = per[cls]
            ok = (p["count"] >= MIN_DOTS) & (p[den] > 0)
            vals = p[num][ok] / p[den][ok] - minus
            out[f"{cls}_sd"] = float(vals.std()) if len(vals) > 1 else 0.0
        spread = float(np.hypot(out["band_sd"], out["interior_sd"]))
        out["passed"] = bool(abs(out["band"] - out["interior"]) <= 2.0 * spread)
        measures[name] = out

    ratio("close_pair_dots_per_dot", "close", "count")
    ratio("psi6_mean", "psi", "count")
    if "nn" in per["band"]:
        ratio("nn_normalized_mean", "nn", "nn_count")
    if density is not None:
        ratio("coverage_error", "area", "target", minus=1.0)
    return {
        "band_mm": width,
        "tiles": [nx, ny],
        "band_dots": n_band,
        "interior_dots": n_int,
        "measures": measures,
        "passed": all(m["passed"] for m in measures.values()),
    }
