"""Multirate FMI co-simulation master for real-time simulation of controlled mechanical systems."""

__version__ = "0.1.0"

__all__ = ["run", "validate", "info", "sweep", "__version__"]


def __getattr__(name: str):
    """The public API, imported on first use: `master --version` and the workers need none of it."""
    if name in ("run", "validate", "info"):
        from master import api

        return getattr(api, name)
    if name == "sweep":
        from master.sweeps import sweep

        return sweep
    raise AttributeError(f"module 'master' has no attribute {name!r}")
