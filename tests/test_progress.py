"""What a user sees while a job runs: each stage named as it starts, a slow
first start explained (numba compiles the kernels once), the relaxation's line closed
with the iteration it stopped at, and nothing at all when stderr is not a terminal."""

from __future__ import annotations

import io
import time

from optdot.cli import progress as progress_mod
from optdot.cli.progress import ProgressBar


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def _lines(text: str) -> list[str]:
    return [x.strip() for x in text.replace("\r", "\n").splitlines() if x.strip()]


def test_stages_are_named_and_the_bar_ends_where_the_relaxation_stopped(tiny_job):
    from optdot.orchestration.pipeline import generate

    out = _Tty()
    bar = ProgressBar(tiny_job.optimize.max_iter, label="optdot", stream=out)
    p = generate(tiny_job, progress=bar, stage=bar.stage)
    bar.close()
    seen = _lines(out.getvalue())
    starts = [x.split("...")[0] for x in seen if "..." in x]
    assert starts[:1] == ["optdot: throwing darts"]
    assert "optdot: relaxing" in starts and starts[-1] == "optdot: guarantee pass"
    stopped = [x for x in seen if "relaxed, stopped at iteration" in x]
    assert len(stopped) == 1
    assert f"iteration {p.meta['iterations']} of {tiny_job.optimize.max_iter}" in stopped[0]
    assert out.getvalue().endswith("\n")


def test_a_stage_without_news_says_the_kernels_are_compiling(monkeypatch):
    monkeypatch.setattr(progress_mod, "SLOW_START", 0.05)
    out = _Tty()
    bar = ProgressBar(200, label="optdot", stream=out)
    bar.stage("relaxing")
    time.sleep(0.3)
    bar(1, 2.0)
    bar.stage("guarantee pass")
    time.sleep(0.3)
    bar.close()
    text = out.getvalue()
    assert text.count("compiling kernels: first run only") == 2, text
    fast = _Tty()
    bar = ProgressBar(200, stream=fast)
    bar.stage("relaxing")
    bar(1, 2.0)  # news before the timer: no excuse printed
    time.sleep(0.3)
    bar.close()
    assert "compiling" not in fast.getvalue()


def test_nothing_is_drawn_when_stderr_is_not_a_terminal():
    out = io.StringIO()
    bar = ProgressBar(200, stream=out)
    bar.stage("relaxing")
    bar(5, 1.0)
    bar.close()
    assert out.getvalue() == ""


def test_export_names_its_stages(tiny_pattern, tiny_job, tmp_path):
    from optdot.orchestration.pipeline import export

    seen: list[str] = []
    export(tiny_pattern, {"gds": tmp_path / "m.gds"}, tiny_job, stage=seen.append)
    assert seen == ["QA gate", "writing"]
