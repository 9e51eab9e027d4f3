"""Parameter studies: one scenario run over many parameter values on a Dask cluster
(`master.sweep`, `master sweep`), and the executor that `master bench` shares."""

from master.sweeps.cases import SweepError
from master.sweeps.study import SweepResult, sweep

__all__ = ["sweep", "SweepResult", "SweepError"]
