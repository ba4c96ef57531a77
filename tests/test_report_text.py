"""Numbers as a reader of the gate's lines and the report meets them: a JND just under
the limit is not printed as the limit, and a grain figure is not held to random dots' 1
where the map itself changes."""

from __future__ import annotations

import pytest

from optdot.quality.gate import jnd_text
from optdot.quality.report import _grain_text


@pytest.mark.parametrize(
    "value, text",
    [(0.9973, "0.997"), (0.99996, "0.99996"), (1.0, "1.00"), (1.004, "1.004"), (0.16, "0.16"),
     (2.345, "2.35"), (0.5, "0.50")],
)  # fmt: skip
def test_a_jnd_is_printed_on_its_side_of_the_limit(value, text):
    assert jnd_text(value) == text


def _grain(fill):
    return {"grain": {"window_mm": [0, 0, 10, 10], "fill_range": fill, "dots": 5000,
                      "s_ka_0.3_1": 1.5, "s_ka_1_3": 0.2}}  # fmt: skip


def test_grain_on_a_changing_map_is_not_judged_against_random_dots():
    even = _grain([0.2, 0.2])
    assert "<b>1.5</b>" in _grain_text(even) and "Random (Poisson) dots give 1" in _grain_text(even)
    changing = _grain([0.05, 0.3])
    text = _grain_text(changing)
    assert "<b>" not in text and "not compared with random dots' 1" in text
