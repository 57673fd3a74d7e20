"""Batch runs of a study on local worker processes or a dask cluster, resumable, writing the run's tables.

- :mod:`hcid.pipeline.studies`: the stages simulate, identify and calibrate W,
  and :func:`run_study`, which chains them with the sweep.
- :mod:`hcid.pipeline.sweep`: ``sweep-w``, the selection over the W grid and its thresholds.
- :mod:`hcid.pipeline.fit_hc`: ``fit-hc``, the parametric HC fit and residual
  analysis of every selected model.
- :mod:`hcid.pipeline.analyse`: ``hcid analyse``, a measured study end to end, in its steps
  (its twins in :mod:`hcid.pipeline.twins`, each run's evidence in :mod:`hcid.pipeline.evidence`).
- :mod:`hcid.pipeline.execution`: :class:`Execution`, how a command's work runs (workers,
  backend, progress, BLAS single-threaded); :mod:`hcid.pipeline.parallel` its worker pool.
- :mod:`hcid.pipeline.rundir`: which config a run directory belongs to.
"""

from hcid.pipeline.execution import Execution
from hcid.pipeline.parallel import BACKENDS, check_backend, parallel_map
from hcid.pipeline.rundir import check_run_dir
from hcid.pipeline.studies import (
    CalibrationRun,
    IdentifyRun,
    SimulationRun,
    StudyRun,
    calibrate_study,
    identify_study,
    run_study,
    simulate_study,
)
from hcid.pipeline.sweep import SweepRun, sweep_study


def __getattr__(name: str):
    """``fit_hc_study`` and ``HCFitRun`` on first use: fit-hc's modules import python-control and
    scipy.stats (about 1 s), which simulating and identifying never need."""
    if name in ("HCFitRun", "fit_hc_study"):
        from hcid.pipeline import fit_hc as fit

        return getattr(fit, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), "HCFitRun", "fit_hc_study"})


__all__ = [
    "BACKENDS",
    "CalibrationRun",
    "Execution",
    "HCFitRun",
    "IdentifyRun",
    "SimulationRun",
    "StudyRun",
    "SweepRun",
    "calibrate_study",
    "check_backend",
    "check_run_dir",
    "fit_hc_study",
    "identify_study",
    "parallel_map",
    "run_study",
    "simulate_study",
    "sweep_study",
]
