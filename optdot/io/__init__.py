"""Files of optdot's own: pattern CSV/NPZ, and atomic replacement of any output."""
