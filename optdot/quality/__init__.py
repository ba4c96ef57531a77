"""Stage 3, QA: metrics measured with engines independent of the optimizer, the gate,
and the HTML/JSON report."""
