"""Run one of the paper's scenes from Python and print what it shows.

    python examples/run_scene.py [hydraulic-manipulator | dc-motor-arm]

Writes results/<scene>.csv and results/<scene>.png and prints the run summary.
"""

from __future__ import annotations

import sys
from pathlib import Path

import master

ROOT = Path(__file__).resolve().parents[1]


def main(scene: str = "hydraulic-manipulator") -> int:
    path = ROOT / "models" / scene / "SystemStructure.ssd"
    out = ROOT / "results"
    result = master.run(path, output=out / f"{scene}.csv", plot=out / f"{scene}.png")
    s = result.summary
    print(f"{scene}: real-time factor {s.real_time_factor:.1f} (serial), results in {out}")
    d = result.data
    for name in d.dtype.names[1:]:
        print(f"  {name:26} start {d[name][0]: .6g}  end {d[name][-1]: .6g}")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:2]))
