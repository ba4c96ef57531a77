"""A prism sheet (BEF) over an ideal Lambertian recycler (issue 60): the on-axis gain of one
90° film (index 1.58, flat base, no thickness, lossless) by an independent numpy tracer
written here, against optdot's whole stack, for cavity reflectances R.

The independent tracer: a Lambertian source plane that is also a Lambertian reflector of
reflectance R, under the film. A ray meets the film at a uniform place in the prisms'
period; the cross-section (x across the grooves, period 1, z up, prisms 0.5 high) is
explicit segments over five periods, each leg the nearest segment it meets (or, inside,
the flat base); unpolarised Fresnel and total internal reflection at each; the direction
along the grooves kept by the facets. What the film sends back down is re-emitted
Lambertian with chance R. The gain is the radiance within 5° of the normal (per unit
source flux) over a bare Lambertian's.

optdot: the same as a direct-lit stack (``tests/test_prism_sheet.py``'s ``IDEAL``): LEDs
on a cavity of reflectance R, mirror walls (an endless plane), a clear film of index 1,
with and without the sheet; the gain is the efficiency times the on-axis luminance, with
the sheet over without.

Run: python benchmarks/bef_recycler.py [--rays 2e6] [--reflectances 0,0.5,0.8,0.9,0.95,0.99]

Printed per R: the independent gain ± its sigma, optdot's ± its sigma, their difference in
sigma; seconds; at the end the peak memory.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
from _common import machine, peak_rss_mb  # noqa: E402

N_FILM = 1.58
H = 0.5  # a 90° prism's height over its period
#: ``(x0, z0, x1, z1, nx, nz)``: the facets of five periods, each normal out into the air
SEGS = np.array(
    [
        seg
        for k in range(-2, 3)
        for seg in (
            (k, 0.0, k + 0.5, H, -(0.5**0.5), 0.5**0.5),
            (k + 0.5, H, k + 1.0, 0.0, 0.5**0.5, 0.5**0.5),
        )
    ]
)


def fresnel(cos_i: np.ndarray, n1, n2) -> np.ndarray:
    """Unpolarised Fresnel reflectance at incidence cosines ``cos_i`` (>= 0), 1 past the
    critical angle."""
    sin_t = n1 / n2 * np.sqrt(np.clip(1 - cos_i**2, 0, None))
    cos_t = np.sqrt(np.clip(1 - sin_t**2, 0, None))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return np.where(sin_t >= 1, 1.0, 0.5 * (rs**2 + rp**2))


def lambert(rng, m: int) -> np.ndarray:
    """``[m, 3]`` Lambertian directions going up."""
    a, phi = rng.random(m), 2 * np.pi * rng.random(m)
    s = np.sqrt(a)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.sqrt(1 - a)], 1)


def through_film(rng, d: np.ndarray, max_legs: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Rays of directions ``d`` ``[m, 3]`` (in air, going up) meeting the film from below:
    ``(up [m] bool, out [m, 3])``, whether each leaves above and its direction then."""
    m = len(d)
    d = d.copy()
    x, z = rng.random(m), np.zeros(m)
    done, up = np.zeros(m, bool), np.zeros(m, bool)
    back = rng.random(m) < fresnel(d[:, 2], 1.0, N_FILM)  # off the base
    d[back, 2] *= -1
    done |= back
    inside = ~back
    d[inside, :2] /= N_FILM
    d[inside, 2] = np.sqrt(1 - d[inside, 0] ** 2 - d[inside, 1] ** 2)
    for _ in range(max_legs):
        act = np.flatnonzero(~done)
        if not len(act):
            break
        xa, za, da, ins = x[act], z[act], d[act], inside[act]
        p, w = da[:, 0], da[:, 2]
        best, seg = np.full(len(act), np.inf), np.full(len(act), -1)
        for j, (x0, z0, x1, z1, _, _) in enumerate(SEGS):
            ex, ez = x1 - x0, z1 - z0
            den = p * ez - w * ex
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((x0 - xa) * ez - (z0 - za) * ex) / den
                s = ((x0 - xa) * w - (z0 - za) * p) / den
            ok = (t > 1e-10) & (s >= 0) & (s <= 1) & (t < best) & np.isfinite(t)
            best, seg = np.where(ok, t, best), np.where(ok, j, seg)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_base = np.where(ins & (w < 0), -za / w, np.inf)
        base = t_base < best
        free = ~ins & (seg < 0)  # in air with no facet ahead: gone
        done[act[free]] = True
        up[act[free]] = d[act[free], 2] > 0
        if base.any():  # the flat base from inside: out below, or back up
            i = act[base]
            x[i], z[i] = xa[base] + p[base] * t_base[base], 0.0
            refl = rng.random(len(i)) < fresnel(-w[base], N_FILM, 1.0)
            d[i[refl], 2] *= -1
            out = i[~refl]
            d[out, :2] *= N_FILM
            d[out, 2] = -np.sqrt(np.clip(1 - d[out, 0] ** 2 - d[out, 1] ** 2, 0, None))
            done[out], inside[out] = True, False
        hit = (seg >= 0) & ~base
        if hit.any():  # a facet: Fresnel, total internal reflection, Snell
            i, s = act[hit], SEGS[seg[hit]]
            x[i], z[i] = xa[hit] + p[hit] * best[hit], za[hit] + w[hit] * best[hit]
            nv = np.stack([s[:, 4], np.zeros(len(i)), s[:, 5]], 1)
            dv = d[i]
            c = np.sum(dv * nv, 1)  # > 0: leaving the prism
            n1 = np.where(inside[i], N_FILM, 1.0)
            n2 = np.where(inside[i], 1.0, N_FILM)
            refl = rng.random(len(i)) < fresnel(np.abs(c), n1, n2)
            eta = n1 / n2
            cos_t = np.sqrt(np.clip(1 - eta**2 * (1 - c**2), 0, None))
            tran = eta[:, None] * (dv - c[:, None] * nv) + (np.sign(c) * cos_t)[:, None] * nv
            new = np.where(refl[:, None], dv - 2 * c[:, None] * nv, tran)
            d[i] = new / np.linalg.norm(new, axis=1)[:, None]
            inside[i] = np.where(refl, inside[i], ~inside[i])
        x -= np.floor(x)
    return up, d


def independent_gain(r: float, rays: int, seed: int, cone_deg: float = 5.0) -> tuple:
    """``(gain, sigma)``: the on-axis radiance over the film on a recycler of reflectance
    ``r``, per unit source flux, over a Lambertian's (1 / pi), by :func:`through_film`."""
    rng = np.random.default_rng(seed)
    cos_c = np.cos(np.radians(cone_deg))
    acc, hits = 0.0, 0
    for start in range(0, rays, 1_000_000):
        d = lambert(rng, min(1_000_000, rays - start))
        while len(d):
            up, out = through_film(rng, d)
            u = out[up]
            near = u[:, 2] > cos_c
            hits += int(near.sum())
            acc += float(np.sum(1 / u[near, 2]))  # radiance: per projected solid angle
            d = lambert(rng, int((rng.random(int((~up).sum())) < r).sum()))
    gain = acc / rays / (2 * np.pi * (1 - cos_c)) * np.pi
    return gain, gain / np.sqrt(max(hits, 1))


def optdot_gain(r: float, rays: int, folder: Path) -> tuple:
    """``(gain, sigma)``: optdot's stack (the module's) with the sheet over without."""
    from optdot.config.schema import load_job
    from optdot.optics.simulate import simulate

    stack = (
        "[domain]\nwidth = 20.0\nheight = 20.0\n[dots]\ndiameter = 0.046\n"
        '[backlight]\nkind = "direct"\n'
        'frame = 1.0\nframe_finish = "specular"\n[backlight.leds]\npitch = [5.0, 5.0]\nsize = 0.2\n'
        f'profile = "lambertian"\n[backlight.cavity]\ngap = 1.5\nreflector = {r}\n'
        "[backlight.film]\nthickness = 0.2\nrefractive_index = 1.0\n"
    )
    np.savetxt(folder / "m.csv", np.full((2, 2), 0.001), delimiter=",")
    on, rel = [], []
    for sheet in ("", '[[backlight.sheets]]\nkind = "prism"\ngrooves = "y"\n'):
        (folder / "j.toml").write_text(stack + sheet + '[density]\ngrid = "m.csv"\n')
        s = simulate(load_job(folder / "j.toml").bench, rays, 3).summary()
        a = s["angles"]
        on.append(s["efficiency"] * a["on_axis"])
        rel.append(a["on_axis_sigma"] / a["on_axis"])
    gain = on[1] / on[0]
    return gain, gain * float(np.hypot(*rel))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=float, default=2e6, help="rays a tracer, each R")
    ap.add_argument("--reflectances", default="0,0.5,0.8,0.9,0.95,0.99", help="cavity R")
    a = ap.parse_args()
    print(machine())
    print("| R | independent | optdot | difference |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k, r in enumerate(float(v) for v in a.reflectances.split(",")):
            t = time.perf_counter()
            g1, s1 = independent_gain(r, int(a.rays), 1000 + k)
            t1 = time.perf_counter() - t
            g2, s2 = optdot_gain(r, int(a.rays), Path(tmp))
            t2 = time.perf_counter() - t - t1
            z = (g2 - g1) / float(np.hypot(s1, s2))
            print(
                f"| {r:g} | {g1:.3f} ± {s1:.3f} ({t1:.0f} s) | {g2:.3f} ± {s2:.3f} ({t2:.0f} s) "
                f"| {z:+.1f} σ |",
                flush=True,
            )
    print(f"peak {peak_rss_mb():.0f} MB (one process)")


if __name__ == "__main__":
    main()
