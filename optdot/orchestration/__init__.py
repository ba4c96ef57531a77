"""The runs of the pipeline: a job read once, turned into the values every stage takes,
and the stages run over the panel in one process or over its tiles.

* :mod:`.job_settings`: where a job becomes the values every stage takes, once a run.
* :mod:`.preflight`: what a job will cost and whether it fits, before anything runs.
* :mod:`.pipeline`: ``generate`` (throw → relax → finish over the panel, in this
  process), ``qa`` and ``export``; ``generate_to`` picks one process or tiles.
* :mod:`.tiled` and :mod:`.tiling`: the same stages over tiles (plan, tasks, their
  order on workers), resumable, to a dataset.
"""
