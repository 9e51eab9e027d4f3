"""Optional extras (pyproject.toml): which command needs which, checked before any work is done.

A command whose extra is not installed stops at once with one line naming the pip command,
instead of a ModuleNotFoundError after the run (or an empty results folder)."""

from __future__ import annotations

import importlib.util

# command, the option that brings the need (None: always), the extra, the modules it imports
NEEDS: tuple[tuple[str, str | None, str, tuple[str, ...]], ...] = (
    ("run", "plot", "plot", ("matplotlib",)),
    ("plot", None, "plot", ("matplotlib",)),
    ("sweep", None, "sweep", ("distributed", "pyarrow")),
    ("sweep", "series", "sweep", ("zarr", "xarray")),
    ("sweep", "plot", "plot", ("matplotlib",)),
    ("bench", None, "sweep", ("distributed",)),  # its configurations run on the sweep's executor
    ("bench", None, "plot", ("matplotlib",)),  # it always draws the work-precision plot
)


class MissingExtra(Exception):
    """An optional extra a command needs is not installed; the message names the pip command."""


def installed(module: str) -> bool:
    """Whether `module` can be imported (looked up, not imported: some take a second to load)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a finder refusing it, a module half-set in sys.modules
        return False


def require(command: str, options: dict[str, object] | None = None) -> None:
    """Raise MissingExtra for the first extra `command` needs with these options (name -> value,
    a need counts when its option's value is set) whose modules are not all installed."""
    for cmd, option, extra, modules in NEEDS:
        if cmd != command or (option is not None and not (options or {}).get(option)):
            continue
        missing = [m for m in modules if not installed(m)]
        if missing:
            flag = f" --{option}" if option else ""
            raise MissingExtra(
                f"`master {command}{flag}` needs {', '.join(missing)}, which is not installed: "
                f"pip install 'master[{extra}]'"
            )
