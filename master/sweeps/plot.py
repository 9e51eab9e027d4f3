"""A sweep's metrics against its varied parameters: one panel per metric.

x is the first varied parameter; a second one gives a line per value (a grid of at most
MAX_LINES values) or the colour of each point (random designs). Cases that did not finish are
marked with a red x at the bottom of the panel. Each axis names its quantity's unit where the
sweep knows it (SweepResult.units).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MAX_LINES = 10


def plot_sweep(result, png: str | Path, title: str = "") -> None:
    import matplotlib.pyplot as plt

    fig = sweep_figure(result, title)
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120, metadata={"Title": title})
    plt.close(fig)


def sweep_figure(result, title: str = ""):
    """The figure of `plot_sweep` (a matplotlib Figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result.rows
    varied = list(result.points[0]) if result.points else []
    fixed = {"case", "index", "status", "message", "wall_time", "t_end", *varied}
    metrics = [k for k in rows[0] if k not in fixed and "(" not in k] if rows else []
    if not metrics:  # no --metric: the final value of each recorded column
        metrics = [k for k in (rows[0] if rows else {}) if k.startswith("final(")]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(9.5, 2.6 * len(metrics) + 0.6), squeeze=False)
    x_name = varied[0]
    ok = [r for r in rows if r["status"] == "ok"]
    bad = [r for r in rows if r["status"] != "ok"]
    units = result.units
    for ax, metric in zip(axes[:, 0], metrics, strict=True):
        _panel(ax, ok, x_name, varied[1] if len(varied) > 1 else None, metric, units)
        if bad:
            low = ax.get_ylim()[0]
            ax.plot([r[x_name] for r in bad], [low] * len(bad), "x", color="red", ms=8, label="failed")
        ax.set_ylabel(_label(metric, units))
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the points
    axes[-1, 0].set_xlabel(_label(x_name, units))
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _label(name: str, units: dict[str, str | None]) -> str:
    """An axis label: the quantity and its unit, if known."""
    return f"{name} [{units[name]}]" if units.get(name) else name


def _panel(ax, rows: list[dict], x_name: str, by: str | None, metric: str, units: dict) -> None:
    x = np.array([r[x_name] for r in rows])
    y = np.array([r[metric] for r in rows])
    if by is None:
        order = np.argsort(x)
        ax.plot(x[order], y[order], "o-", label=metric)
        return
    z = np.array([r[by] for r in rows])
    levels = np.unique(z)
    if len(levels) <= MAX_LINES:
        for level in levels:
            sel = z == level
            order = np.argsort(x[sel])
            unit = f" {units[by]}" if units.get(by) else ""
            ax.plot(x[sel][order], y[sel][order], "o-", label=f"{by} = {level:g}{unit}")
    else:
        points = ax.scatter(x, y, c=z, cmap="viridis", s=18, label=metric)
        ax.figure.colorbar(points, ax=ax, label=_label(by, units))
