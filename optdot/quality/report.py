"""The QA report: one self-contained HTML file (plots embedded as PNG) and the JSON."""

from __future__ import annotations

import base64
import html
import io
import json
import textwrap
from pathlib import Path

import numpy as np

from ..figures import angles_judged, angles_pair, halo_pair, luminance_pair, structure_text
from ..io.atomic import atomic_path, expect_tail
from .gate import QAResult, jnd_text
from .visibility import BLOB_JND


def write_json(result: QAResult, path: str | Path) -> None:
    """Write the JSON report atomically (every number, for scripts)."""
    text = json.dumps(result.to_json(), indent=2, sort_keys=True, default=_jsonable)
    with atomic_path(path, expect_tail(b"}\n", str(path))) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")


def write_reports(result: QAResult, reports, title: str = "optdot QA") -> None:
    """The JSON and/or HTML of ``reports`` (``{"json": path, "html": path}``); the HTML
    links the JSON when both lie in one folder, else folds the numbers in."""
    json_path, html_path = reports.get("json"), reports.get("html")
    if json_path:
        write_json(result, json_path)
    if html_path:
        link = None
        if json_path and Path(json_path).parent.resolve() == Path(html_path).parent.resolve():
            link = Path(json_path).name
        write_html(result, html_path, title=title, json_link=link)


def _provenance_text(result: QAResult) -> str:
    """The traceability block: what was judged, against what, by which optdot, when."""
    p = result.provenance
    if not p:
        return ""

    def file(e) -> str:
        if not e:
            return "—"
        digest = e.get("sha256") or "unreadable"
        return f"<code>{html.escape(e['path'])}</code> (SHA-256 <code>{digest[:16]}…</code>)"

    rows = [
        ("pattern", file(p.get("pattern")) if p.get("pattern") else "in memory"),
        ("job", file(p.get("job")) if p.get("job") else "none (defaults)"),
        ("seed", html.escape(str(p.get("seed")))),
        ("optdot", html.escape(str(p.get("optdot")))),
        ("date (UTC)", html.escape(str(p.get("date_utc")))),
    ]
    rows += [("input", file(e)) for e in p.get("inputs", [])]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<table id='provenance' class='prov'>{body}</table>"


#: The report's terms, in words (the report's last section before the numbers).
GLOSSARY = """<h2 id="terms">Terms</h2><dl>
<dt>limit, level</dt><dd>A gating check fails (✘, verdict FAIL) when its value is over its
<i>limit</i>. An advisory check (marked "advisory", ⚠ when over) never fails the gate: its
limit is the <i>level</i> above which the verdict is PASS WITH WARNINGS. "limit 1" on the
JND line is such a level unless <code>qa.max_jnd</code> makes it a gate.</dd>
<dt>JND</dt><dd>Just-noticeable difference: 1 is seen by half of the viewers at the
viewing distance and luminance named, under 0.5 by nobody.</dd>
<dt>SEMU index</dt><dd>A blob's contrast over the just-noticeable contrast SEMI D31
gives for its area (1.97/S<sup>0.33</sup> + 0.72 %, S in mm²): a second opinion that
ignores the viewing distance; over 1 is visible by that rule.</dd>
<dt>ψ6 coherence</dt><dd>ψ6 is the six-fold bond order of each dot's neighbours (1 in a
hexagonal lattice, near 0 in disorder); its mean over 2 mm patches measures local
crystals whose orientation repeats: the moiré risk (optdot's patterns about 0.02; the gate's limit 0.1).</dd>
<dt>coverage / map − 1 in the worst 0.1 mm band</dt><dd>The dots' area over the map's
in bands 0.1 mm wide at the same distance from a wall (panel edge, hole, keep-out,
zero-fill border), summed along every wall: the band furthest from 0, as a share. A
bright line along the edges reads positive, a dark one negative.</dd>
<dt>k·a, S</dt><dd>S is the structure factor (the dots' power spectrum, 1 for random
dots); k·a a wavelength in units of the dot spacing a (k·a = 2π is one spacing). Low S at
k·a under 1 (several spacings) means no long-wavelength grain a viewer could see.</dd>
</dl>"""


def _mark(c) -> str:
    return "✔" if c.passed else ("⚠" if c.advisory else "✘")


def _row_class(c) -> str:
    return "pass" if c.passed else ("warn" if c.advisory else "fail")


def _warnings_text(result: QAResult) -> str:
    """Under the verdict: what the warnings are, in words a user acts on."""
    items = [
        f"<li>{html.escape(c.name)}: {_fmt(c.value)} (level {_fmt(c.limit)})</li>"
        for c in result.warnings
    ]
    items += [f"<li>not checked: {html.escape(k)}</li>" for k in result.skipped]
    if not items:
        return ""
    return (
        "<div id='warnings'><p>The gate passed, but:</p><ul>"
        + "".join(items)
        + "</ul><p>See <i>Will a viewer see it?</i> below for what to do.</p></div>"
    )


def write_html(
    result: QAResult, path: str | Path, title: str = "optdot QA", json_link: str | None = None
) -> None:
    """Write the HTML report atomically: verdict first, then what a viewer will see, the
    plots, and a link to the JSON (``json_link``, relative to the HTML) or the numbers.

    Everything drawn comes from ``result`` (its plot arrays are bounded in size), so a
    panel of any dot count gives a report of the same size."""
    figs = _figures(result)
    seen = _visibility_section(result) + _simulation_section(result)
    verdict = result.verdict
    color = {"PASS": "#1a7f37", "FAIL": "#cf222e"}.get(verdict, "#9a6700")
    rows = "".join(
        f"<tr class='{_row_class(c)}'><td>{_mark(c)}</td><td>{html.escape(c.name)}</td>"
        f"<td>{_fmt(c.value)}</td><td>{_fmt(c.limit)}</td>"
        f"<td>{html.escape(', '.join(f'({x:.3f}, {y:.3f})' for x, y in c.where[:5]))}</td></tr>"
        for c in result.checks
    )
    rows += "".join(
        f"<tr class='skip'><td>–</td><td>not checked: {html.escape(k)}</td>"
        "<td></td><td></td><td></td></tr>"
        for k in result.skipped
    )
    imgs = "".join(
        f"<figure><img alt='{html.escape(cap)}' src='data:image/png;base64,{b64}'>"
        f"<figcaption>{html.escape(cap)}</figcaption></figure>"
        for cap, b64 in figs
    )
    m = result.metrics
    box = m["box_mm"]
    if json_link is None:
        numbers = (
            "<details><summary>All numbers (JSON)</summary><pre>"
            + html.escape(json.dumps(m, indent=1, default=_jsonable))
            + "</pre></details>"
        )
    else:
        numbers = (
            f"<p>Every number, for scripts: <a href='{html.escape(json_link)}'>"
            f"{html.escape(json_link)}</a>.</p>"
        )
    doc = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1200px}}
.verdict{{font-size:2em;color:#fff;background:{color};padding:.3em .6em;display:inline-block}}
table{{border-collapse:collapse}}tr.fail{{background:#ffebe9}}tr.warn{{background:#fff8c5}}
tr.skip{{color:#666}}td,th{{border:1px solid #ccc;padding:.2em .5em}}
figure{{display:inline-block;margin:.5em}}img{{max-width:560px}}</style></head><body>
<h1>{html.escape(title)}</h1><div class="verdict" id="verdict">{verdict}</div>
{_warnings_text(result)}
{_provenance_text(result)}
<p>{m["dots"]:,} dots, {_dots_text(m)}, panel {box[2] - box[0]:.3f} × {box[3] - box[1]:.3f} mm</p>
<h2>Gate</h2><table><tr><th></th><th>check</th><th>value</th><th>limit</th><th>where (mm, first 5)</th></tr>{rows}</table>
{seen}
<h2>Spacing, order and coverage</h2>
<p>The overview shows the fill the dots realise, close pairs and defects; the zoom the
densest region at true scale; the histogram the nearest-neighbour distances against the
collision and too-close limits; the coverage map the error after smoothing; the spectrum a
peak where the pattern orders (moiré risk).</p>{_grain_text(m)}{imgs}{GLOSSARY}<h2>Numbers</h2>{numbers}</body></html>
"""
    with atomic_path(path, expect_tail(b"</html>\n", str(path))) as tmp:
        tmp.write_text(doc, encoding="utf-8")


def _visibility_section(result: QAResult) -> str:
    """The "will a viewer see it" section: JND map, the worst blobs, what to do."""
    vis = result.metrics.get("visibility")
    if not vis:
        return (
            "<h2>Will a viewer see it?</h2><p>Not computed: the visibility check compares "
            "the luminance with the target map; give the job (<code>--job</code>).</p>"
        )
    jnd_png = _jnd_figure(result)
    blobs = "".join(
        f"<tr><td>{b['x_mm']:.2f}, {b['y_mm']:.2f}</td><td>{b.get('kind', '')}</td>"
        f"<td>{b['area_mm2']:.3g}</td>"
        f"<td>{b['contrast_percent']:+.3f}</td><td>{'-' if b['jnd'] < 0 else '+'}{jnd_text(abs(b['jnd']))}</td><td>{b['semu']:.2f}</td></tr>"
        for b in vis["blobs"][:10]
    )
    table = (
        "<table><tr><th>blob at (mm)</th><th>kind</th><th>area (mm²)</th><th>contrast (%)</th>"
        "<th>JND</th><th>SEMU index |C|/C<sub>jnd</sub></th></tr>" + blobs + "</table>"
        if blobs
        else f"<p id='no-blobs'>No region reaches {BLOB_JND:g} JND: nothing to list.</p>"
    )
    x, y = vis["max_jnd_at_mm"]
    where = ""
    if "viewing_area_mm" in vis:
        a = vis["viewing_area_mm"]
        px, py = vis["panel_max_jnd_at_mm"]
        where = (
            f" in the viewing area ({a[0]:g}..{a[2]:g} x {a[1]:g}..{a[3]:g} mm, the dashed "
            f"frame; the bezel hides the rest); over the whole panel {jnd_text(vis['panel_max_jnd'])}"
            f" at ({px:.2f}, {py:.2f}) mm"
        )
    coarse = (
        " The grid was coarsened to bound memory; fine detail is smoothed."
        if vis["grid_coarsened"]
        else ""
    )
    return f"""<h2>Will a viewer see it?</h2>
<p>Viewing: <b>{html.escape(str(vis["view"]))}</b>, {vis["distance_mm"]:g} mm,
{vis["luminance_cd_m2"]:g} cd/m², stack blur (PSF sigma) {vis["psf_sigma_mm"]:g} mm.
Largest |JND| <b>{jnd_text(vis["max_jnd"])}</b> at ({x:.2f}, {y:.2f}) mm{where};
{vis["blobs_over_1_jnd"]} region(s) over 1 JND.{coarse}</p>
<p>The map is the luminance the dots give after the stack's blur, relative to the target
map (the intended gradient is not an error), as contrast against the eye's 2° surround,
filtered by Barten's contrast sensitivity at this distance and luminance: 1 JND is just
visible (50 % of observers), red brighter, blue darker. Regions over 1 JND are what a
viewer will notice; under 0.5 nobody will. <b>What to do</b>: a blob inside the panel
with a map of its shape is a coverage error of the pattern (regenerate with another seed
or more iterations, check the map's resolution); a line along an edge is the dots'
layering against the wall (see the wall profile below; patterns from optdot 0.4 on do not
layer: regenerate); speckle all over means the stack blurs less than the grain of
the dots: smaller dots (<code>[dots] diameter = [lo, hi]</code>) or more diffusion. The
PSF and the gate (<code>qa.max_jnd</code>, off by default) should be calibrated against a
photographed test plate (README, "The verdict").</p>
<figure><img style="max-width:100%" alt="JND map" src="data:image/png;base64,{jnd_png}">
<figcaption>JND map over the panel</figcaption></figure>
{table}
<p>SEMU index: |C| over C<sub>jnd</sub> = 1.97/S<sup>0.33</sup> + 0.72 % (S the blob's
area in mm²; the commonly cited form of SEMI D31), a second opinion that ignores distance;
blobs are regions where |JND| ≥ 0.5, bright and dark ones apart (a bright line beside a
dark band is two blobs).</p>"""


def _grain_text(m) -> str:
    """One paragraph on the long-wavelength grain (``metrics["grain"]``), or nothing."""
    g = m.get("grain")
    if not g:
        return ""
    w = g["window_mm"]
    fill = g.get("fill_range")
    fills = f", fill {fill[0]:.3g}–{fill[1]:.3g}" if fill else ""
    changes = bool(fill) and fill[1] > MAP_CHANGES * fill[0]
    s = f"{g['s_ka_0.3_1']:.2g}" if changes else f"<b>{g['s_ka_0.3_1']:.2g}</b>"
    if changes:  # the map's own gradient is long-wavelength structure: not grain
        judged = (
            "The map's fill changes inside this window, and its own gradient is structure "
            "at these wavelengths that random dots do not have: S here is not compared with "
            "random dots' 1; judge the grain on a part of the panel where the map is even."
        )
    else:
        judged = "Random (Poisson) dots give 1; optdot's own pattern on an even map ~0.00001."
    return (
        f"<p>Grain: structure factor S = {s} at wavelengths of 6–20 "
        f"dot spacings (k·a 0.3–1) and {g['s_ka_1_3']:.2g} at 2–6 (k·a 1–3), over "
        f"({w[0]:.1f}, {w[1]:.1f})–({w[2]:.1f}, {w[3]:.1f}) mm around the densest square "
        f"({g['dots']:,} dots{fills}). {judged}</p>"
    )


#: A grain window whose highest fill exceeds its lowest by this factor is on a map that
#: changes (its S is not judged against random dots').
MAP_CHANGES = 1.1


def _simulation_section(result: QAResult) -> str:
    """The simulated luminance (``qa --simulation``) and its figures, or nothing."""
    sim = result.metrics.get("simulation")
    if not sim or "luminance" not in result.arrays:
        return ""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    lum, ext, spots = result.arrays["luminance"]
    w, h = ext[1] - ext[0], ext[3] - ext[2]
    halo = result.arrays.get("halo")
    angles = result.arrays.get("angles")
    heights = [max(2.5, min(6.0, 5.2 * h / max(w, 1e-9) + 1.2))]
    heights += [5.6] * (bool(halo) + bool(angles))
    fig, axes = plt.subplots(
        len(heights), 2, figsize=(12, sum(heights)), squeeze=False, layout="constrained",
        gridspec_kw={"height_ratios": heights},
    )  # fmt: skip
    noise = sim.get("luminance_rms_noise") or 0.0
    im, _ = luminance_pair(axes[0], lum, ext, noise)
    lo, hi = im.get_clim()
    over = bool(lum.size) and (float(lum.max()) > hi or float(lum.min()) < lo)
    fig.colorbar(
        im, ax=list(axes[0]), label="luminance / mean", shrink=0.8,
        extend="both" if over else "neither",
    )  # fmt: skip
    area = sim.get("viewing_area_mm")
    for ax in axes[0]:
        for sx, sy, _ in spots:
            ax.add_patch(
                Circle(
                    (sx, sy), 0.5 * (sim.get("spot_diameter_mm") or 0), fill=False, color="k",
                    lw=0.8,
                )
            )  # fmt: skip
        _frame(ax, area)
    if halo:
        halo_pair(axes[1], halo)
    if angles:
        angles_pair(axes[len(heights) - 1], angles, sim["angles"])
    fig.suptitle("Simulated luminance (circles: 9-point spots)", fontsize=10)
    png = _png_base64(fig)
    halo_text = ""
    if halo:
        hx, hy = halo["led_mm"]
        w50, w10 = (
            f"{v:.3g} mm" if v is not None else "beyond the panel"
            for v in (halo.get("width50_mm"), halo.get("width10_mm"))
        )
        halo_text = (
            f" The LED at ({hx:.2f}, {hy:.2f}) mm lit alone (below): its halo is {w50} wide at "
            f"half its peak and {w10} at a tenth."
        )
    if angles and not angles_judged(sim["angles"]):
        halo_text += (
            f" By direction (below): {sim['angles'].get('on_axis_rays', 0)} rays left within 5° "
            "of the normal, too few to judge the on-axis luminance and its half angles."
        )
    elif angles:
        a = sim["angles"]
        halves = ", ".join(
            f"{k} {'over 87.5°' if v is None else f'{v:.1f}°'}"
            for k, v in (a.get("half_luminance_deg") or {}).items()
        )
        halo_text += (
            f" By direction (below): on-axis luminance {_n(a.get('on_axis'), '.3f')} ± "
            f"{_n(a.get('on_axis_sigma'), '.3f')} of a Lambertian's of the same flux; half "
            f"luminance at {html.escape(halves)}."
        )
    region = (
        "the viewing area (dashed)"
        if area
        else f"the panel less {sim['border_mm']:g} mm"
        if sim.get("border_mm")
        else "the panel"
    )
    outside = ""
    if sim.get("outside_max") is not None:
        ox, oy = sim["outside_max_at_mm"]
        outside = (
            f" Outside it the brightest bin is {sim['outside_max']:.3f} of the mean, at "
            f"({ox:.2f}, {oy:.2f}) mm."
        )
    mode = "the real dots" if sim.get("mode") == "dots" else "the map's coverage"
    other = (
        ""
        if sim.get("same_pattern")
        else (f" <b>It traced another pattern ({sim.get('dots'):,} dots, not these).</b>")
    )
    return f"""<h2>Simulated luminance</h2>
<p>From <code>{html.escape(str(sim.get("file")))}</code>: {sim.get("rays", 0):,} rays through
{mode}.{other} Efficiency <b>{_n(sim.get("efficiency"), ".1%")}</b> ± {_n(sim.get("efficiency_sigma"), ".2%")};
9-point uniformity <b>{_n(sim.get("uniformity_9point"), ".3f")}</b> ± {_n(sim.get("uniformity_9point_sigma"), ".3f")};
luminance RMS {_n(sim.get("luminance_rms"), ".2%")} over {region}
(Monte Carlo noise alone {_n(sim.get("luminance_rms_noise"), ".2%")}: {html.escape(structure_text(sim))}), min {_n(sim.get("luminance_min"), ".3f")},
max {_n(sim.get("luminance_max"), ".3f")} of the mean.{outside}{halo_text}{_band_text(sim)} The bins as traced carry the rays' noise; the smoothed view beside them
shows what is structure. Compare it with the JND map above: the JND map
judges the dots against the map, this one the map and the dots against the LEDs.</p>
<figure><img style="max-width:100%" alt="simulated luminance" src="data:image/png;base64,{png}"></figure>
"""


def _turn(angle: float) -> np.ndarray:
    """``[2, 2]`` the matrix turning row vectors counter-clockwise by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, s], [-s, c]])


def _band_text(sim: dict) -> str:
    """The process's tolerance band as traced (the real dots grown to each end of the
    gain), in words; empty without one."""
    band = sim.get("tolerance_band")
    if not band:
        return ""
    ends = "; ".join(
        f"at {g * 1e3:.4g} µm per edge 9-point {_n(u, '.3f')}, RMS {_n(r, '.2%')}, "
        f"min/max {_n(lo, '.3f')}/{_n(hi, '.3f')}"
        for g, u, r, lo, hi in zip(
            band["gain_mm"], band["uniformity_9point"], band["luminance_rms"],
            band["luminance_min"], band["luminance_max"], strict=True,
        )
    )  # fmt: skip
    return f" Across the process's gain tolerance (the real dots grown each way): {ends}."


def _jnd_figure(result: QAResult) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img, ext = result.arrays["jnd"]
    w, h = ext[1] - ext[0], ext[3] - ext[2]
    fig, ax = plt.subplots(figsize=(10, max(2.5, min(8.0, 10 * h / max(w, 1e-9) + 1))))
    v = max(2.0, float(np.abs(img).max()) if img.size else 2.0)
    v = min(v, 5.0)
    im = ax.imshow(img, origin="lower", extent=ext, cmap="RdBu_r", vmin=-v, vmax=v)
    _colorbar(fig, ax, im, "JND (1 = just visible)", "both" if np.abs(img).max() > v else "neither")
    for ring in result.arrays.get("rings", []):
        loop = np.vstack([ring, ring[:1]])
        ax.plot(loop[:, 0], loop[:, 1], color="k", lw=0.7)
    _frame(ax, result.metrics["visibility"].get("viewing_area_mm"))
    for b in result.metrics["visibility"]["blobs"][:10]:
        if abs(b["jnd"]) >= 1:
            ax.plot(b["x_mm"], b["y_mm"], marker="o", mfc="none", mec="k", ms=12)
    ax.set(
        xlabel="x (mm)", ylabel="y (mm)", title=_wrap("What a viewer sees (circles: over 1 JND)")
    )
    return _png_base64(fig)


def _frame(ax, area) -> None:
    """The viewing area ``(x0, y0, x1, y1)`` mm drawn dashed on ``ax`` (nothing for
    None)."""
    if area:
        ax.plot(
            [area[0], area[2], area[2], area[0], area[0]],
            [area[1], area[1], area[3], area[3], area[1]],
            color="k", lw=1.0, ls="--",
        )  # fmt: skip


def _n(v, spec: str) -> str:
    """A figure of a simulation file in ``spec``, or "n/a" where it holds none (a JSON
    null: no light reached the measured region)."""
    return "n/a" if v is None else format(v, spec)


def _wrap(title: str, width: int = 52) -> str:
    """A figure title broken into lines that fit the narrowest figure (5 in at 90 dpi)."""
    return "\n".join(textwrap.wrap(title, width))


def _colorbar(fig, ax, im, label: str, extend: str = "neither") -> None:
    """A colour bar beside ``ax``, exactly as tall as the plot (an image of equal aspect
    is shorter than its axes' box, which a plain colour bar spans); ``extend`` draws the
    arrows of values beyond the scale (LED hot spots, say)."""
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    cax = make_axes_locatable(ax).append_axes("right", size="4%", pad=0.08)
    fig.colorbar(im, cax=cax, label=label, extend=extend)


def _png_base64(fig) -> str:
    """``fig`` as a base64 PNG (90 dpi, no software stamp: same figure, same bytes); closes it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    if fig.get_layout_engine() is None:  # a constrained layout lays itself out
        fig.tight_layout()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _figures(result: QAResult) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection, LineCollection, PolyCollection

    out: list[tuple[str, str]] = []
    a = result.arrays
    m = result.metrics

    def save(fig, caption):
        out.append((caption, _png_base64(fig)))

    img, ext = a["overview"]
    fig, ax = plt.subplots(figsize=(6, 4))
    im = ax.imshow(img, origin="lower", extent=ext, interpolation="nearest")
    _colorbar(fig, ax, im, "fill fraction")
    for ring in a["rings"]:
        loop = np.vstack([ring, ring[:1]])
        ax.plot(loop[:, 0], loop[:, 1], color="white", lw=0.7)
    for key, style in (
        ("close_mid", dict(ls="", marker=",", color="orange")),
        ("collision_mid", dict(ls="", marker="x", color="r", ms=8)),
        ("defects", dict(ls="", marker="+", color="m", ms=8)),
    ):
        pts = a[key]
        if len(pts):
            ax.plot(pts[:, 0], pts[:, 1], **style)
    ax.set(
        xlabel="x (mm)",
        ylabel="y (mm)",
        title=_wrap("Overview: coverage; close pairs (orange), defects (x, +)"),
    )
    save(fig, "overview")

    tx0, ty0, tx1, ty1 = a["tile"]
    s = min(1.0, tx1 - tx0)
    fig, ax = plt.subplots(figsize=(5, 5))
    zxy, feet, seg = a["zoom"]
    if feet.kind.round:
        zd = feet.diameter
        ax.add_collection(
            EllipseCollection(
                zd, zd, 0, units="xy", offsets=zxy, offset_transform=ax.transData, fc="k"
            )
        )
    else:  # the true footprints, each at its size and angle
        tol = 0.002 * float(np.median(feet.extent())) if feet.n else 1e-4
        ax.add_collection(
            PolyCollection([feet.outline(k, tol) + zxy[k] for k in range(feet.n)], fc="k")
        )
    band = m.get("tolerance_band")
    if band and feet.n:  # the mask each dot prints from, at the print's scale
        g = band["gain_mm"][1]
        tol = 0.002 * float(np.median(feet.extent()))
        rings = [
            feet.kind.parallel_outline(feet.size[k], -g, tol) @ _turn(feet.angles[k]) + zxy[k]
            for k in range(feet.n)
        ]
        ax.add_collection(PolyCollection(rings, fc="none", ec="deepskyblue", lw=0.6))
    if len(seg):
        ax.add_collection(LineCollection(seg, colors="orange", linewidths=1))
    masked = "; the mask it prints from in blue" if band else ""
    ax.set(
        xlim=(tx0, tx0 + s),
        ylim=(ty0, ty0 + s),
        aspect="equal",
        xlabel="x (mm)",
        ylabel="y (mm)",
        title=_wrap(f"True-scale zoom of the densest region (close pairs in orange{masked})"),
    )
    save(fig, "densest region")

    turned = m.get("orientation")
    if turned and "histogram_5deg_from_-90" in turned:
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.stairs(turned["histogram_5deg_from_-90"], np.arange(-90, 91, 5), fill=True)
        err = (
            f"; off the field by {turned['field_error_mean_deg']:.2g}° on average, "
            f"{turned['field_error_max_deg']:.2g}° at most"
            if "field_error_max_deg" in turned
            else ""
        )
        ax.set(
            xlabel="long axis, degrees from +x",
            ylabel="dots",
            xlim=(-90, 90),
            xticks=np.arange(-90, 91, 30),
            title=_wrap("Angles of the dots' long axes, per 5°" + err),
        )
        save(fig, "angles")

    fig, ax = plt.subplots(figsize=(6, 3.5))
    if a["nn_hist"] is not None:
        counts, edges = a["nn_hist"]
        ax.stairs(counts, edges, fill=True, color="steelblue")
    if "close_distance_mm" in m:  # one size: the thresholds are centre distances
        ax.axvline(m["collision_distance_mm"] * 1e3, color="red", label="collision")
        ax.axvline(m["close_distance_mm"] * 1e3, color="orange", label="too close")
        ax.legend()
    ax.set(
        xlabel="nearest-neighbour distance (µm)",
        ylabel="dots",
        title=_wrap("Nearest-neighbour distances"),
    )
    save(fig, "nearest-neighbour histogram")

    if "coverage_error" in a:
        rel, ext = a["coverage_error"]
        fig, ax = plt.subplots(figsize=(6, 4))
        v = max(float(np.abs(rel).max()), 1e-3)
        im = ax.imshow(
            rel * 100, origin="lower", extent=ext, cmap="RdBu_r", vmin=-v * 100, vmax=v * 100
        )
        _colorbar(fig, ax, im, "coverage error (%)")
        ax.set(xlabel="x (mm)", ylabel="y (mm)", title=_wrap("Coverage vs target (1 mm Gaussian)"))
        save(fig, "coverage error")

    if "walls" in a and "walls" in m:
        prof = a["walls"]
        mid = 0.5 * (prof.edges[1:] + prof.edges[:-1])
        lim = m["walls"]["limit"] * 100
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.axhspan(-lim, lim, color="0.9", label="advisory band")
        ax.plot(mid, prof.relative * 100, marker="o", ms=3)
        ax.axhline(0, color="k", lw=0.5)
        ax.set(
            xlabel="distance from the nearest wall (mm)",
            ylabel="coverage / map - 1 (%)",
            title=_wrap("Coverage against distance from walls (edges, holes, zero-fill borders)"),
        )
        ax.legend()
        save(fig, "wall profile")

    freq, power = a["spectrum"]
    if len(freq):
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.plot(freq, power)
        ax.set(
            xlabel="spatial frequency (1/mm)",
            ylabel="power (Poisson = 1)",
            title=_wrap("Radially averaged power spectrum, densest 2 mm tile"),
        )
        save(fig, "spectrum")
    return out


def _dots_text(m: dict) -> str:
    """The dots' footprints in words: ``diameter 46.0 µm`` (a range when sizes vary), or
    a shaped kind with each size parameter (a range where it varies)."""
    feet = m.get("footprint_mm")
    if not feet:
        return f"diameter {_diameter_text(m['diameter_mm'])}"
    sizes = []
    for name, r in feet.items():
        if name == "kind":
            continue
        lo, hi = r["min"] * 1e3, r["max"] * 1e3
        sizes.append(f"{name} {lo:.4g} µm" if hi - lo < 1e-6 else f"{name} {lo:.4g}–{hi:.4g} µm")
    return f"{html.escape(feet['kind'])}: " + ", ".join(sizes)


def _diameter_text(d) -> str:
    if isinstance(d, dict):
        return f"{d['min'] * 1e3:.1f}–{d['max'] * 1e3:.1f} µm"
    return f"{d * 1e3:.1f} µm"


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _jsonable(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)
