"""Multirate FMI co-simulation master for real-time simulation of controlled mechanical systems."""

__version__ = "0.1.0"

from master.api import info, run, validate  # noqa: E402  (the public API)
from master.sweeps import sweep  # noqa: E402

__all__ = ["run", "validate", "info", "sweep", "__version__"]
