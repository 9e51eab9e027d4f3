"""Everything in docs/evidence/, by one command: the work-precision sweeps of the three scenes,
the paper's experiments 1 and 2, the stability limits against extrapolation order and the error
budget of the paper scenes' dual-rate runs.

Run: .venv/bin/python examples/paper_evidence.py   (about 5 to 10 minutes on 2 cores)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "evidence"
SCENES = [
    ROOT / "docs" / "evidence" / "oscillator" / "oscillator.ssd",
    ROOT / "models" / "hydraulic-manipulator" / "SystemStructure.ssd",
    ROOT / "models" / "dc-motor-arm" / "SystemStructure.ssd",
]
SCRIPTS = ["paper_hydraulic_manipulator.py", "paper_dc_motor_arm.py", "paper_stability.py", "error_budget.py"]


def main() -> int:
    for scene in SCENES:  # one after the other: wall times are measured, nothing else runs
        log = OUT / f"{scene.parent.name}-bench.txt"
        with open(log, "w") as f:
            cmd = [
                sys.executable,
                "-m",
                "master",
                "bench",
                str(scene.relative_to(ROOT)),
                "--out",
                str(OUT.relative_to(ROOT)),
                "--repeats",
                "5",
            ]
            subprocess.run(cmd, check=True, stdout=f, stderr=subprocess.DEVNULL, cwd=ROOT)
        print(f"wrote {log.relative_to(ROOT)}")
    for script in SCRIPTS:
        log = OUT / f"{Path(script).stem}.txt"
        with open(log, "w") as f:
            cmd = [sys.executable, str(ROOT / "examples" / script), "--out", str(OUT)]
            subprocess.run(cmd, check=True, stdout=f, stderr=subprocess.DEVNULL, cwd=ROOT)
        print(f"wrote {log.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
