"""optdot's light-guide tracer against one no one here wrote: pvtrace (PyPI; a Python
tracer of light trapped in plates by total internal reflection, with Fresnel at every
face). The same small guide in both: a 10 x 10 x 1 mm PMMA slab with bare edges, 0.2 mm
white dots (albedo 1, Lambertian) on a grid at fill 0.3 on the bottom face as a pvtrace
surface delegate that decides dot or no dot from the hit point, one Lambertian LED on the
left edge, nothing under the guide. Extraction, edge and bottom losses and the light the
LED edge turns back must agree within the Monte Carlo noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from optdot.config.schema import job_from_dict
from optdot.optics.simulate import simulate
from optdot.pattern import Pattern

from .conftest import bare_guide, load_pvtrace, pvtrace_left_led

W, H, T, N, D, FILL = 10.0, 10.0, 1.0, 1.49, 0.2, 0.3
RAYS = 4000


def _dots() -> np.ndarray:
    r = D / 2
    pitch = math.sqrt(math.pi * r * r / FILL)
    gx, gy = np.meshgrid(np.arange(r, W - r, pitch), np.arange(r, H - r, pitch))
    return np.column_stack([gx.ravel(), gy.ravel()])


def _pvtrace(centres: np.ndarray, rays: int) -> dict[str, int]:
    """Rays per fate traced by pvtrace."""
    pv = load_pvtrace()
    from scipy.spatial import cKDTree

    tree = cKDTree(centres)

    class Dots(pv.FresnelSurfaceDelegate):
        def on_dot(self, ray, container) -> bool:
            x, y, z = ray.position  # the box's frame: centred on the origin
            if container.name != "guide" or abs(z + T / 2) > 1e-6:
                return False
            return tree.query([x + W / 2, y + H / 2])[0] <= D / 2

        def reflectivity(self, surface, ray, geometry, container, adjacent):
            if self.on_dot(ray, container):
                return 1.0
            return super().reflectivity(surface, ray, geometry, container, adjacent)

        def reflected_direction(self, surface, ray, geometry, container, adjacent):
            if self.on_dot(ray, container):
                u, v = np.random.uniform(), np.random.uniform()
                s = math.sqrt(u)
                return (
                    s * math.cos(2 * math.pi * v),
                    s * math.sin(2 * math.pi * v),
                    math.sqrt(1 - u),
                )
            return super().reflected_direction(surface, ray, geometry, container, adjacent)

    world = pv.Node(name="world", geometry=pv.Sphere(radius=100.0, material=pv.Material(1.0)))
    guide = pv.Node(
        name="guide",
        geometry=pv.Box((W, H, T), material=pv.Material(N, surface=pv.Surface(delegate=Dots()))),
        parent=world,
    )
    guide.location = (W / 2, H / 2, T / 2)
    pvtrace_left_led(pv, world, 5.0, 2.0, T)
    scene = pv.Scene(world)
    np.random.seed(1)
    fates = {"extracted": 0, "lost_bottom": 0, "lost_edges": 0, "not_coupled": 0, "missed": 0}
    assert pv.__version__
    for ray in scene.emit(rays):
        history = pv.photon_tracer.follow(scene, ray, maxsteps=20000)
        events = [e for _, e in history]
        assert events[-1] != pv.Event.KILL
        crossings = [r for r, e in history if e == pv.Event.TRANSMIT]
        if events[1] == pv.Event.REFLECT:
            fates["not_coupled"] += 1
        elif not crossings:  # passed beside the guide (born at its corner)
            fates["missed"] += 1
        else:
            z = crossings[-1].position[2]
            key = (
                "extracted"
                if abs(z - T) < 1e-6
                else "lost_bottom"
                if abs(z) < 1e-6
                else ("lost_edges")
            )
            fates[key] += 1
    return fates


@pytest.mark.slow
def test_pvtrace_agrees_on_extraction_and_losses():
    centres = _dots()
    raw = bare_guide(W, H, T, N, {"diameter": D}, 5.0, 2.0)
    job = job_from_dict(raw, need_map=False)
    ours = simulate(job.bench, 1_000_000, seed=3, dots=Pattern(centres, D, (0.0, 0.0, W, H)))
    theirs = _pvtrace(centres, RAYS)
    assert theirs["missed"] <= RAYS // 500
    emitted = RAYS - theirs["missed"]
    injected = emitted - theirs["not_coupled"]
    shares = ours.summary()["shares"]
    for key in ("extracted", "lost_edges", "lost_bottom"):
        p = theirs[key] / injected
        sigma = math.sqrt(max(p * (1 - p), 1e-4) / injected)
        assert abs(shares[key] - p) < 3.5 * sigma, (key, shares[key], p, sigma)
    p = theirs["not_coupled"] / emitted
    assert abs(ours.fates["not_coupled"] / ours.rays - p) < 3.5 * math.sqrt(p * (1 - p) / emitted)
    # the comparison can tell: the extraction differs by a quarter without the dots
    bare = simulate(job.bench, 200_000, seed=3, dots=Pattern(centres[:0], D, (0.0, 0.0, W, H)))
    assert bare.efficiency < 0.05 < theirs["extracted"] / injected


def test_a_missing_pvtrace_fails_the_comparisons_naming_its_extra(monkeypatch):
    """Without pvtrace (the `validation` extra) a comparison fails, never skips."""
    import sys

    monkeypatch.setitem(sys.modules, "pvtrace", None)
    with pytest.raises(pytest.fail.Exception, match=r"pip install '\.\[validation\]'"):
        load_pvtrace()
