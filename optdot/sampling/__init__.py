"""Stage 1, initial dots: low-discrepancy dart throwing (paper §2.1) on a scrambled Sobol
sequence."""
