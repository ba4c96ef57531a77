"""The relaxation stage: OptDot (L-BFGS through the formulation's stages, then the
correction) or the MD baseline of §2.2, one result either way."""

from __future__ import annotations

import numpy as np

from ..relax.circles import hex_radius
from ..relax.md import MDForce, md_relax
from ..relax.optdot import Progress, relax_staged
from ..relax.result import RelaxResult
from .beyond_walls import with_phantoms
from .correction import long_wavelength
from .settings import StageSettings


def relax(
    s: StageSettings,
    xy0: np.ndarray,
    start: np.ndarray | None = None,
    frozen: np.ndarray | None = None,
    progress: Progress | None = None,
    lowpass: bool = True,
) -> RelaxResult:
    """Relax the dots thrown at ``xy0`` (``[n, 2]`` mm, Morton order for speed): OptDot
    through the formulation's stages, or the MD baseline; one result either way.

    Args:
        start: ``[n, 2]`` positions to start from (default ``xy0``; containers stay on
            ``xy0``).
        frozen: ``[n]`` bool, dots held still (a tile's neighbours).
        progress: ``progress(iteration, value)``; a true return halts.
        lowpass: run the formulation's long-wavelength correction and its hard-core
            iterations (:func:`long_wavelength`) after the relaxation. Tiles relax without
            (False): the correction runs once their seams are relaxed, blended over
            windows that span the seams (:func:`correction_region`), and the hard core in
            their guarantee task (:func:`hard_core`).
    """
    opt = s.optimize
    rho = s.density.at(xy0)
    if opt.method == "md":
        if start is not None or frozen is not None:
            raise ValueError("the MD baseline relaxes a whole panel, not a tile")
        r0 = 0.5 * s.diameter
        law = MDForce(
            core=s.min_distance,
            spacing=2.0 * hex_radius(rho, r0),
            decay=opt.md_decay,
            cutoff=opt.md_cutoff,
        )
        return md_relax(
            xy0, law, s.box, r0, steps=opt.max_iter, step=opt.md_step, skin=opt.skin,
            callback=progress,
        )  # fmt: skip
    rho = s.container_fill(xy0)
    form = s.formulation
    diameters = s.rule_diameters(xy0)
    phantom = None
    if form.phantoms and len(xy0):
        xy0, rho, start, frozen, diameters, phantom = with_phantoms(
            s, xy0, rho, start, frozen, diameters
        )
    res = relax_staged(
        s.problem,
        form,
        xy0,
        rho,
        s.relax,
        progress,
        start=start,
        frozen=frozen,
        diameters=diameters,
        phantom=phantom,
    )
    if lowpass and (form.lowpass or form.lowpass_core_iter) and s.relax.max_iter > 0:
        res = long_wavelength(s, res, xy0, rho, frozen, diameters, phantom)
    if phantom is not None:
        res.xy = np.ascontiguousarray(res.xy[~phantom])
    return res
