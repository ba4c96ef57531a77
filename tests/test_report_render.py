"""The HTML report renders in headless Chromium (skipped where no Chromium is installed)."""

import shutil
import subprocess

import pytest
from click.testing import CliRunner

from optdot.cli import main

from .conftest import SAMPLES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt install chromium)")
def test_html_report_screenshot(tmp_path):
    job = SAMPLES / "tiny" / "job.toml"
    r = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv"), "-q"])
    assert r.exit_code == 0
    html = tmp_path / "r.html"
    r = CliRunner().invoke(
        main, ["qa", str(tmp_path / "p.csv"), "--job", str(job), "--html", str(html)]
    )
    assert r.exit_code == 0
    shot = tmp_path / "shot.png"
    subprocess.run(
        [
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
            f"--screenshot={shot}",
            "--window-size=1200,1600",
            html.as_uri(),
        ],
        check=True,
        timeout=120,
        capture_output=True,
    )
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
