"""Printing a mask: a process's figures (:mod:`.process`), and what a mask draws for a
printed pattern and the print a mask read back makes (:mod:`.mask`)."""
