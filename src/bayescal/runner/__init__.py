"""Run a simulator over a design, cached per run and resumable (see :mod:`bayescal.runner.run`).

Modules
-------
:mod:`~bayescal.runner.run`
    :func:`run_design` and its backends (serial, worker processes, Dask).
:mod:`~bayescal.runner.cache`
    The per-run cache (``runs/<key>.npz``, ``failures/<key>.json``) and its ledger.
:mod:`~bayescal.runner.keys`
    Fingerprints of the simulator and the boundary conditions, and the run keys.
:mod:`~bayescal.runner.sandbox`
    The worker subprocesses that run one simulation at a time and can be killed.
"""

from bayescal.runner.cache import Progress
from bayescal.runner.keys import forcing_fingerprint, run_key, simulator_fingerprint
from bayescal.runner.run import BACKENDS, Backend, RunFailure, RunResults, run_design

__all__ = [
    "BACKENDS",
    "Backend",
    "Progress",
    "RunFailure",
    "RunResults",
    "forcing_fingerprint",
    "run_design",
    "run_key",
    "simulator_fingerprint",
]
