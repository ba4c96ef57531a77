"""Tiled generation for panels one process cannot hold: the plan, the tasks, the run."""
