"""The Speos 3D-texture mapping (exporters.speos), read back by a parser written from the
Speos user guide's description (count line, then ``x y z ix iy iz jx jy jz kx ky kz``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from optdot.io.dataset_write import save_dataset
from optdot.io.patterns import save_pattern

from .conftest import SAMPLES, optdot


def parse(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(origins [n, 3], directions [n, 6], scales [n, 3])``; every line has 12 numbers."""
    lines = path.read_text(encoding="ascii").splitlines()
    n = int(lines[0])
    rows = [ln.split(" ") for ln in lines[1:]]
    assert len(rows) == n and all(len(r) == 12 for r in rows)
    a = np.array(rows, dtype=np.float64)
    return a[:, :3], a[:, 3:9], a[:, 9:]


run = optdot  # the command in a child process (tests/conftest.py)


@pytest.mark.slow
def test_fixed_size_dots_map_to_their_centres_at_scale_one(tmp_path, tiny_pattern):
    src = tmp_path / "p.npz"
    save_pattern(tiny_pattern, src)
    out = tmp_path / "p.OPT3DMapping"
    job = SAMPLES / "tiny" / "job.toml"
    r = run("export", src, "--job", job, "--speos", out)
    assert r.returncode == 0, r.stderr
    xyz, dirs, scale = parse(out)
    np.testing.assert_allclose(xyz[:, :2], tiny_pattern.xy, atol=5e-7)
    assert np.all(xyz[:, 2] == 0)
    assert np.all(dirs == [1, 0, 0, 0, 1, 0])
    assert np.all(scale == 1.0)


@pytest.mark.slow
def test_varying_sizes_scale_by_the_reference_diameter(tmp_path, tiny_pattern):
    rng = np.random.default_rng(3)
    d = np.round(rng.uniform(0.030, 0.046, tiny_pattern.n), 6)
    p = replace(tiny_pattern, diameter=d)
    src = tmp_path / "p.npz"
    save_pattern(p, src)
    out = tmp_path / "p.OPT3DMapping"
    r = run(
        "export", src, "--speos", out, "--speos-reference-diameter", 0.05, "--force", "--no-job"
    )
    assert r.returncode == 0, r.stderr
    _, _, scale = parse(out)
    np.testing.assert_allclose(scale, np.repeat((d / 0.05)[:, None], 3, axis=1), atol=5e-7)


@pytest.mark.slow  # over 1.5 s
def test_a_dataset_streams_the_same_file(tmp_path, tiny_pattern):
    save_pattern(tiny_pattern, tmp_path / "p.npz")
    save_dataset(tiny_pattern, tmp_path / "p.parquet")
    job = SAMPLES / "tiny" / "job.toml"
    for src in ("p.npz", "p.parquet"):
        r = run("export", tmp_path / src, "--job", job, "--speos", tmp_path / f"{src}.map")
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "p.npz.map").read_bytes() == (tmp_path / "p.parquet.map").read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("ref", ["0", "-1", "inf"])
def test_a_bad_reference_diameter_is_one_line(tmp_path, tiny_pattern, ref):
    save_pattern(tiny_pattern, tmp_path / "p.npz")
    out = tmp_path / "p.OPT3DMapping"
    r = run("export", tmp_path / "p.npz", "--speos", out, "--speos-reference-diameter", ref)
    assert r.returncode != 0 and not out.exists()
    assert "speos-reference-diameter" in r.stderr and "Traceback" not in r.stderr
