"""3-D dots against pvtrace with mesh geometry (issue 60): the guide of
``tests/test_dot_profile_pvtrace.py`` with bumps of any size, height and spacing, traced by
pvtrace (float64 meshes, the material across a surface found by what holds the point past
it) and by optdot, fate by fate, with pvtrace's noise; and how many rays pvtrace sent from
one raised dot into a neighbour (optdot follows them too, since session 40), then pvtrace
again with those rays lost under the guide, as optdot lost them before. With
``--mirror``, both trace the guide over a perfect mirror lying on the bumps' tips (optdot
since session 41: what the mirror returns comes up among the bumps), pvtrace once.

Needs pvtrace: pip install '.[test,validation]'.

Run: python benchmarks/profiles_pvtrace.py [--rays 2000] [--pitch 0.5] [--diameter 0.4]
     [--height 0.1] [--mirror]

Printed per tracer: extracted, lost under the guide, lost at the edges (shares of the
injected rays), each optdot share's distance from pvtrace's in pvtrace's sigma, and the
polar histogram (15° bins) of the extracted, per injected ray; then seconds; at the end
the peak memory.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.pattern import Pattern  # noqa: E402
from tests.test_dot_profile_pvtrace import (  # noqa: E402
    FATES,
    POLAR_EDGES,
    H,
    W,
    _cap_mesh,
    _layout,
    _optdot,
    _pvtrace,
)


def _row(name: str, shares: dict, z: dict | None, polar: np.ndarray, seconds: float) -> None:
    cells = "  ".join(
        f"{k} {shares[k]:.4f}" + (f" ({z[k]:+.1f} sigma)" if z else "") for k in FATES
    )
    print(f"{name:<32} {cells}  polar/15° {np.round(polar, 4).tolist()}  {seconds:.0f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=int, default=2000, help="pvtrace's rays (optdot: 10^6)")
    ap.add_argument("--pitch", type=float, default=0.5, help="grid pitch, mm")
    ap.add_argument("--diameter", type=float, default=0.4, help="bump diameter, mm")
    ap.add_argument("--height", type=float, default=0.1, help="bump height, mm")
    ap.add_argument("--mirror", action="store_true", help="a perfect mirror on the tips")
    a = ap.parse_args()
    print(machine())
    xy, _ = _layout(a.pitch)
    under = f", over a mirror {a.height} mm under the face" if a.mirror else ""
    print(f"{len(xy)} bumps {a.diameter} mm across, {a.height} mm high, {a.pitch} mm apart{under}")
    t = time.time()
    dots = {"diameter": a.diameter, "profile": "bump", "height": a.height}
    ours = _optdot(dots, Pattern(xy, a.diameter, (0.0, 0.0, W, H)), mirror=a.mirror)
    injected = ours.rays - ours.fates["not_coupled"]
    mine = np.add.reduceat(ours.angles.counts.sum(axis=1), np.arange(0, 18, 3)) / injected
    _row("optdot (10^6 rays)", ours.summary()["shares"], None, mine, time.time() - t)
    for lose in (False,) if a.mirror else (False, True):
        t = time.time()
        with pytest.MonkeyPatch.context() as mp:
            meshes = [_cap_mesh(a.diameter / 2, a.height) for _ in xy]
            fates, polar = _pvtrace(
                meshes, xy, mp.setattr, a.rays, lose_neighbours=lose,
                mirror=a.height if a.mirror else None,
            )  # fmt: skip
        n = sum(fates[k] for k in FATES)
        shares = {k: fates[k] / n for k in FATES}
        z = {
            k: (ours.summary()["shares"][k] - p) / math.sqrt(max(p * (1 - p), 1e-4) / n)
            for k, p in shares.items()
        }
        name = "pvtrace, neighbours lost" if lose else "pvtrace"
        hist = np.histogram(polar, bins=POLAR_EDGES)[0] / n
        _row(f"{name} ({a.rays} rays)", shares, z, hist, time.time() - t)
        print(
            f"  rays meeting a neighbour from the air: {fates['neighbour']} "
            f"({fates['neighbour'] / n:.1%} of the injected), unfinished {fates['other']}"
        )
    print(f"peak {peak_rss_mb():.0f} MB (one process)")


if __name__ == "__main__":
    main()
