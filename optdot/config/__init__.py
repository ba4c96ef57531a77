"""Stage 0, the job: TOML schema and reader, density-grid files, the validated :class:`Job`."""
