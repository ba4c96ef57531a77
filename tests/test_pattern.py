import io

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from optdot.io.patterns import format_fixed6


@settings(max_examples=50, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(0, 30), st.integers(1, 4)),
        elements=st.floats(-1e5, 1e5, allow_nan=False),
    )
)
def test_fixed6_matches_savetxt(values):
    values = np.round(values, 6)
    buf = io.StringIO()
    np.savetxt(buf, values, fmt="%.6f", delimiter=",")
    assert format_fixed6(values) == buf.getvalue().encode("ascii")
