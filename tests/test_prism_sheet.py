"""The prism sheet (a BEF, :mod:`optdot.optics.faces.prism_sheet`): closed forms for the
geometry (retroreflection at normal incidence, Snell through one facet), symmetry across
the grooves' axis, the job's keys, and its gain over a recycling cavity."""

from __future__ import annotations

import json
import math

import numba as nb
import numpy as np
import pytest

from optdot.optics.faces.prism_sheet import meet_prism
from optdot.optics.rays import ray_state
from optdot.optics.tables import CROSS, F_COLS, F_SHEET_T, F_SPREAD, F_SPREAD_SIG, NEW_LEG

from .conftest import cli, one_error


def _row(n: float = 1.58, apex: float = 90.0, along_y: bool = True) -> tuple:
    f = np.zeros(F_COLS)
    f[F_SHEET_T], f[F_SPREAD], f[F_SPREAD_SIG] = n, float(along_y), math.radians(apex / 2)
    return tuple(f)


@nb.njit
def _meet(count, up, dx, dy, dz, f):  # pragma: no cover - compiled
    out = np.zeros((count, 4))
    for i in range(count):
        state, act, a, b, c = meet_prism(ray_state(9, i), f, up, dx, dy, dz)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = act, a, b, c
    return out


def test_light_at_normal_incidence_or_along_the_grooves_is_sent_back():
    """A 90° prism of index 1.58 meets a normal ray at 45° inside, over the critical angle
    (39.3°): total internal reflection at both facets sends everything back down (the
    base's Fresnel reflection too); a ray at 30° along the grooves meets the facets at
    48°, also over it. Every direction stays a unit vector."""
    for d in ((0.0, 0.0, 1.0), (0.0, math.sin(math.radians(30)), math.cos(math.radians(30)))):
        out = _meet(20_000, True, *d, _row())
        assert np.all(out[:, 0] == NEW_LEG) and np.all(out[:, 3] < 0), d
        assert np.allclose(np.linalg.norm(out[:, 1:], axis=1), 1.0)


def test_light_through_one_facet_leaves_as_snell_says():
    """A ray at 30° from the normal across the grooves enters the base at asin(sin 30° /
    n), meets the facet whose normal leans 45° its way at 45° less that, and leaves at
    45° less asin(n sin(that)) from the normal: 0.07°; most rays that cross leave so,
    the rest after other facets. What crosses, what comes back and what is caught add
    up to every ray."""
    n, t = 1.58, math.radians(30)
    out = _meet(50_000, True, math.sin(t), 0.0, math.cos(t), _row(n))
    inside = math.asin(math.sin(t) / n)
    want = math.radians(45) - math.asin(n * math.sin(math.radians(45) - inside))
    crossed = out[out[:, 0] == CROSS]
    angle = np.arctan2(crossed[:, 1], crossed[:, 3])
    assert np.mean(np.abs(angle - want) < 1e-9) > 0.9
    assert 0.5 < len(crossed) / len(out) < 0.8
    assert np.isin(out[:, 0], (CROSS, NEW_LEG)).mean() > 0.99


def test_the_grooves_axis_turns_the_answer():
    """The same rays (same seed) with the grooves along x instead of y: every outcome the
    same, its x and y swapped."""
    t = math.radians(35)
    a = _meet(5_000, True, math.sin(t), 0.1, math.sqrt(1 - math.sin(t) ** 2 - 0.01), _row())
    b = _meet(
        5_000, True, 0.1, math.sin(t), math.sqrt(1 - math.sin(t) ** 2 - 0.01), _row(along_y=False)
    )
    assert np.array_equal(a[:, 0], b[:, 0])
    assert np.allclose(a[:, 1], b[:, 2]) and np.allclose(a[:, 2], b[:, 1])
    assert np.allclose(a[:, 3], b[:, 3])


STACK = """name = "bef"
[domain]
width = 20.0
height = 20.0
[dots]
diameter = 0.046
[backlight]
kind = "direct"
frame = 0.9
[backlight.leds]
pitch = [5.0, 5.0]
size = 0.2
profile = "lambertian"
[backlight.cavity]
gap = 1.5
reflector = 0.9
[backlight.film]
thickness = 0.2
refractive_index = 1.59
[[backlight.sheets]]
kind = "diffuser"
transmittance = 0.65
"""

PRISM = '[[backlight.sheets]]\nkind = "prism"\n'


def test_a_prism_sheet_over_a_recycling_cavity_brightens_the_axis_within_the_published_band(
    tmp_path,
):
    """One 90° prism film over a diffuser and a recycling cavity (reflector 0.9): the
    on-axis luminance (efficiency times the on-axis luminance of a Lambertian of the same
    flux) rises by the 1.4-1.8 published for such a film; the light narrows across the
    grooves (x) more than along them."""
    np.savetxt(tmp_path / "m.csv", np.full((2, 2), 0.001), delimiter=",")
    got = {}
    for name, text in (("plain", STACK), ("bef", STACK + PRISM + 'grooves = "y"\n')):
        job = tmp_path / f"{name}.toml"
        job.write_text(text + '[density]\ngrid = "m.csv"\n')
        rc, err, _ = cli("simulate", job, "--rays", "400000", "--json", tmp_path / f"{name}.json")
        assert rc == 0, err
        got[name] = json.loads((tmp_path / f"{name}.json").read_text())
    on = {k: v["efficiency"] * v["angles"]["on_axis"] for k, v in got.items()}
    gain = on["bef"] / on["plain"]
    assert 1.4 < gain < 1.9, gain
    half = got["bef"]["angles"]["half_luminance_deg"]
    assert half["horizontal"] < 40 < half["vertical"]


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("apex_angle", "180", "apex_angle = 180 must be under 180"),
        ("grooves", '"z"', 'grooves = \'z\' must be "x" or "y"'),
        ("transmittance", "0.5", "transmittance is not a key of a prism sheet"),
        ("refractive_index", "0.9", "refractive_index"),
    ],
)
def test_a_prism_sheet_s_keys_are_checked(tmp_path, key, value, words):
    np.savetxt(tmp_path / "m.csv", np.full((2, 2), 0.001), delimiter=",")
    job = tmp_path / "job.toml"
    job.write_text(STACK + PRISM + f"{key} = {value}\n" + '[density]\ngrid = "m.csv"\n')
    one_error(("check", job), 2, f"backlight.sheets[1].{key}", words)
