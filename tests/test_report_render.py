"""The HTML report renders in headless Chromium (skipped where no Chromium is installed),
and what it shows is the verdict: the verdict box's text in the rendered DOM and its
colour in the screenshot (green PASS, amber PASS WITH WARNINGS, red FAIL)."""

import json
import re
import shutil
import subprocess

import pytest
from click.testing import CliRunner

from optdot.cli import main

from .conftest import SAMPLES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.slow  # over 1.5 s
@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt install chromium)")
def test_html_report_screenshot(tmp_path):
    job = SAMPLES / "tiny" / "job.toml"
    r = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv"), "-q"])
    assert r.exit_code == 0
    html = tmp_path / "r.html"
    r = CliRunner().invoke(
        main,
        [
            "qa", str(tmp_path / "p.csv"), "--job", str(job),
            "--html", str(html), "--json", str(tmp_path / "r.json"),
        ],
    )  # fmt: skip
    assert r.exit_code == 0
    verdict = json.loads((tmp_path / "r.json").read_text())["verdict"]
    shot = tmp_path / "shot.png"
    subprocess.run(
        [*_headless(tmp_path), f"--screenshot={shot}", "--window-size=1200,1600", html.as_uri()],
        check=True,
        timeout=120,
        capture_output=True,
    )
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    dom = subprocess.run(
        [*_headless(tmp_path), "--dump-dom", html.as_uri()],
        check=True,
        timeout=120,
        capture_output=True,
        text=True,
    ).stdout
    shown = re.search(r'<div class="verdict" id="verdict">([^<]*)</div>', dom)
    assert shown and shown.group(1) == verdict
    # the terms are explained; a table of blobs is shown only when there are blobs
    assert 'id="terms"' in dom and "SEMU index" in dom and "limit, level" in dom
    blobs = json.loads((tmp_path / "r.json").read_text())["metrics"]["visibility"]["blobs"]
    assert ("<th>blob at (mm)</th>" in dom) == bool(blobs)
    assert ('id="no-blobs"' in dom) == (not blobs)
    if verdict == "PASS WITH WARNINGS":
        assert "The gate passed, but:" in dom and "not checked" not in dom
    from PIL import Image

    # the verdict box sits under the title, at the left: sample its background
    rgb = Image.open(shot).convert("RGB").getpixel((40, 100))
    want = {"PASS": (0x1A, 0x7F, 0x37), "FAIL": (0xCF, 0x22, 0x2E)}.get(verdict, (0x9A, 0x67, 0x00))
    assert all(abs(a - b) <= 8 for a, b in zip(rgb, want, strict=True)), (rgb, verdict)


def _headless(tmp_path) -> list[str]:
    return [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
    ]
