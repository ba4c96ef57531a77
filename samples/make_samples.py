"""Regenerate the bundled sample jobs and their density grids (deterministic).

Run: python samples/make_samples.py   (writes samples/<name>/job.toml and density.csv)

Each map is a smooth fill-fraction field of the kind a backlight engineer gets from an
optical simulation: low fill where light is strong (near sources), high fill far away.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _centers(width: float, height: float, cell: float) -> tuple[np.ndarray, np.ndarray]:
    nx, ny = round(width / cell), round(height / cell)
    x = (np.arange(nx) + 0.5) * width / nx
    y = (np.arange(ny) + 0.5) * height / ny
    return np.meshgrid(x, y)  # [ny, nx], row 0 = bottom


def led(width=36.0, height=18.0, n_led=4):
    """Edge-lit: LEDs along the bottom edge, hot spots in front of each, steep gradient."""
    X, Y = _centers(width, height, 0.25)
    xs = (np.arange(n_led) + 0.5) * width / n_led
    light = sum(np.exp(-((X - x) ** 2 + (Y + 0.3) ** 2) / (2 * 1.6**2)) for x in xs)
    base = 0.08 + 0.42 * (1 - np.exp(-Y / 6.0))
    return np.clip(base - 0.07 * light, 0.03, 0.55)


def tsuno(width=34.0, height=22.0):
    """Corner-lit: one LED in the lower-left corner with an empty region right next to it."""
    X, Y = _centers(width, height, 0.25)
    rr = np.hypot(X, Y)
    g = 0.10 + 0.35 * (1 - np.exp(-rr / 10.0))
    g[rr < 4.0] = 0.0  # keep-out around the corner LED: no dots
    return np.clip(g, 0.0, 0.55)


def chokka(width=52.0, height=40.0, nx=4, ny=3):
    """Direct-lit: an LED array behind the film; sparse over each LED, dense between."""
    X, Y = _centers(width, height, 0.5)
    px, py = width / nx, height / ny
    dx = (X % px) - px / 2
    dy = (Y % py) - py / 2
    return 0.28 - 0.18 * np.exp(-(dx**2 + dy**2) / (2 * 3.0**2))


def uniform(width=10.0, height=10.0):
    """Uniform 20 % fill: the simplest case, and the one generic blue-noise samplers handle."""
    return np.full((20, 20), 0.2)


def tiny(width=3.0, height=2.0):
    """A small gradient with a zero column, for tests and quick tries."""
    X, Y = _centers(width, height, 0.25)
    g = 0.1 + 0.3 * X / width
    g[:, 0] = 0.0
    return g


SAMPLES = {
    "led": (led, 36.0, 15.0, "edge-lit light guide, 4 LEDs along the bottom edge (~117k dots)"),
    "tsuno": (tsuno, 28.0, 17.0, "corner-lit, empty region around the corner LED (~111k dots)"),
    "chokka": (chokka, 52.0, 40.0, "direct-lit 4x3 LED array behind a diffuser (~287k dots)"),
    "uniform": (uniform, 10.0, 10.0, "uniform 20 % fill (~12k dots)"),
    "tiny": (tiny, 3.0, 2.0, "small gradient with an empty column, for tests (~500 dots)"),
}


def outline_sample(folder: Path) -> None:
    """A real-looking light guide: 24 x 16 mm with a rounded (R 2 mm) top-left corner, a
    45° chamfer bottom-right, a notch for the flex cable on the right edge, an LED
    cut-out in the bottom edge, two M1.6 screw holes, and a keep-out band under the
    frame clip (given in the job as WKT). Outline drawn in a DXF as CAD would: one
    LWPOLYLINE with a bulge for the arc, CIRCLE entities for the holes."""
    import ezdxf

    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 4  # mm
    msp = doc.modelspace()
    bulge = math.tan(math.radians(90) / 4)  # a quarter circle
    shell = [
        (0.0, 0.0, 0.0),
        (9.0, 0.0, 0.0),  # LED cut-out: 6 x 1.2 mm pocket in the bottom edge
        (9.0, 1.2, 0.0),
        (15.0, 1.2, 0.0),
        (15.0, 0.0, 0.0),
        (22.0, 0.0, 0.0),  # chamfer
        (24.0, 2.0, 0.0),
        (24.0, 7.0, 0.0),  # notch for the flex cable
        (21.5, 7.0, 0.0),
        (21.5, 10.0, 0.0),
        (24.0, 10.0, 0.0),
        (24.0, 16.0, 0.0),
        (2.0, 16.0, bulge),  # rounded corner, R 2 mm, centre (2, 14)
        (0.0, 14.0, 0.0),
    ]
    msp.add_lwpolyline(shell, format="xyb", close=True, dxfattribs={"layer": "OUTLINE"})
    for cx, cy in ((3.0, 3.0), (20.0, 13.0)):
        msp.add_circle((cx, cy), 0.8, dxfattribs={"layer": "OUTLINE"})
    doc.saveas(folder / "outline.dxf")
    X, Y = _centers(24.0, 16.0, 0.25)
    light = np.exp(-((X - 12.0) ** 2 + (Y - 0.6) ** 2) / (2 * 2.0**2))
    g = np.clip(0.10 + 0.30 * (1 - np.exp(-np.hypot(X - 12.0, Y) / 6.0)) - 0.06 * light, 0.05, 0.45)
    np.savetxt(folder / "density.csv", g, fmt="%.4f", delimiter=",")
    (folder / "job.toml").write_text(
        "# light guide with a CAD outline: rounded and chamfered corners, a notch, an LED\n"
        "# cut-out, two screw holes (outline.dxf) and a keep-out band (WKT); ~45k dots\n"
        'name = "outline"\n\n[domain]\noutline = "outline.dxf"\n'
        'keep_out = ["POLYGON ((5 15.2, 19 15.2, 19 16.5, 5 16.5, 5 15.2))"]\n'
        "edge_margin = 0.02\n\n"
        '[density]\ngrid = "density.csv"\n\n[dots]\ndiameter = 0.046\n\n'
        '[optimize]\nmethod = "optdot"\nmax_iter = 200\nseed = 1\n'
    )


def edge_lit(width: float, height: float, leds: list[float], lo: float, hi: float):
    """Edge-lit from the bottom edge: fill rising from ``lo`` at the LEDs to ``hi`` at the
    far edge, a little lower in front of each LED (0.5 mm cells)."""
    X, Y = _centers(width, height, 0.5)
    light = sum(np.exp(-((X - x) ** 2 + (Y + 0.2) ** 2) / (2 * 1.2**2)) for x in leds)
    g = lo + (hi - lo) * (1 - np.exp(-Y / (0.45 * height)))
    return np.clip(g - 0.3 * lo * light, 0.5 * lo, hi)


#: The shaped-dot samples: ``name -> (what, dots and orientation TOML, panel, LEDs, fill)``.
SHAPED = {
    "ellipses": (
        "Elongated dots (80 x 40 µm ellipses) on a guide lit from its bottom edge by four "
        "LEDs, each dot's long axis across the light from its nearest LED (22,800 dots)",
        'shape = "ellipse"\nlength = 0.080   # mm, the long axis\nwidth = 0.040\n\n'
        '[orientation]\ntoward = "leds"          # the nearest LED of [light_guide]\n'
        'relative = "perpendicular"  # long axis across the direction from it\n',
        (24.0, 12.0),
        [3.0, 9.0, 15.0, 21.0],
        (0.05, 0.30),
    ),
    "prisms": (
        "Micro-prism footprints (120 x 30 µm rectangles, 5 µm corners) turned toward "
        "eight LEDs on the bottom edge (15,900 dots)",
        'shape = "rounded_rectangle"\nlength = 0.120   # mm\nwidth = 0.030\n'
        "corner_radius = 0.005   # mm; width / 2 makes a capsule, 0 a sharp rectangle\n\n"
        '[orientation]\ntoward = "leds"\nrelative = "perpendicular"\n',
        (24.0, 12.0),
        [1.5, 4.5, 7.5, 10.5, 13.5, 16.5, 19.5, 22.5],
        (0.05, 0.30),
    ),
    "hexagons": (
        "Hexagonal dots (60 µm corner to corner) at random angles on a guide lit from its "
        "bottom edge by four LEDs (24,500 dots)",
        'shape = "polygon"\n'
        "# mm about the dot's centre (their area centroid), in order around it\n"
        "vertices = [[0.030, 0.0], [0.015, 0.025981], [-0.015, 0.025981], [-0.030, 0.0], "
        "[-0.015, -0.025981], [0.015, -0.025981]]\n\n"
        "[orientation]\nrandom = true           # uniform, seeded by optimize.seed\n",
        (24.0, 12.0),
        [3.0, 9.0, 15.0, 21.0],
        (0.05, 0.30),
    ),
}


def shaped_sample(name: str) -> None:
    """Write ``samples/<name>`` of :data:`SHAPED`: its map and a job with its guide."""
    what, dots, (w, h), leds, (lo, hi) = SHAPED[name]
    d = HERE / name
    d.mkdir(exist_ok=True)
    np.savetxt(d / "density.csv", edge_lit(w, h, leds, lo, hi), fmt="%.4f", delimiter=",")
    (d / "job.toml").write_text(
        f'# {what}\nname = "{name}"\n\n[domain]\nwidth = {w}\nheight = {h}\n\n'
        f'[density]\ngrid = "density.csv"\n\n[dots]\n{dots}\n'
        "[optimize]\nseed = 1\ngap = 0.005   # mm, edge to edge\n\n"
        "[light_guide]\nthickness = 0.4\n\n[[light_guide.leds]]\n"
        f'edge = "bottom"\npositions = {leds}\nwidth = 1.0\n'
    )


def lgp_film_guide_map() -> None:
    """The lgp sample's designed map, the guide under the lgp_film sample's film (what
    ``optdot design samples/lgp/job.toml -o map.csv`` writes, seed 0)."""
    from optdot.config.schema import load_job
    from optdot.optics.design import design
    from optdot.optics.writing import map_csv

    got = design(load_job(HERE / "lgp" / "job.toml", need_map=False))
    (HERE / "lgp_film" / "guide_map.csv").write_text(map_csv(got.fill))


def main() -> None:
    lgp_film_guide_map()
    d = HERE / "outline"
    d.mkdir(exist_ok=True)
    outline_sample(d)
    for name in SHAPED:
        shaped_sample(name)
    for name, (fn, w, h, what) in SAMPLES.items():
        d = HERE / name
        d.mkdir(exist_ok=True)
        g = fn(w, h)
        np.savetxt(d / "density.csv", g, fmt="%.4f", delimiter=",")
        (d / "job.toml").write_text(
            f'# {what}\nname = "{name}"\n\n[domain]\nwidth = {w}\nheight = {h}\n\n'
            f'[density]\ngrid = "density.csv"\n\n[dots]\ndiameter = 0.046\n\n'
            f'[optimize]\nmethod = "optdot"\nmax_iter = 200\nseed = 1\n'
        )


if __name__ == "__main__":
    main()
