"""The end-to-end calibration: study file -> design -> ... -> report.

* :mod:`~bayescal.pipeline.stages` -- the stages as plain functions, each of
  the previous stage's result (they compute and never write);
* :mod:`~bayescal.pipeline.predict` -- predictions with bands, and their metrics;
* :mod:`~bayescal.pipeline.keys` -- the stage keys (what each stage depends on)
  and the seeds derived from the study's;
* :mod:`~bayescal.pipeline.budget` -- the memory and disk a study's sizes imply,
  checked before anything is allocated;
* :mod:`~bayescal.pipeline.run` -- the stage runner: :func:`run` runs or
  reuses each stage, writing its artefacts into the study's output folder
  (:mod:`bayescal.store` lists the files), and :func:`load_results` reads
  them back.

::

    res = run(load_study("study.toml"), until="predict", say=print)
"""

from bayescal.pipeline.budget import check_budget
from bayescal.pipeline.keys import stage_keys
from bayescal.pipeline.run import Results, load_results, run, write_study_report
from bayescal.pipeline.stages import Options
from bayescal.store.stages import STAGES

__all__ = [
    "STAGES",
    "Options",
    "Results",
    "check_budget",
    "load_results",
    "run",
    "stage_keys",
    "write_study_report",
]
