"""Multirate FMI co-simulation master for real-time simulation of controlled mechanical systems."""

__version__ = "0.1.0"

from master.api import info, run, validate  # noqa: E402  (the public API)

__all__ = ["run", "validate", "info", "__version__"]
