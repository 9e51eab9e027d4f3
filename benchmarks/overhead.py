"""Master overhead per macro step and real-time factor.

    /work/venv/bin/python benchmarks/overhead.py            # oscillator, serial backend
    /work/venv/bin/python benchmarks/overhead.py --memory   # peak memory, 10^3 vs 10^6 recorded steps

Overhead = (wall time - time inside FMI calls) / macro steps: what the master itself costs.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario


def oscillator(H: Fraction, stop: Fraction, order: int, interpolate: bool) -> Scenario:
    """The two-mass oscillator (parameter set A), one RK4 step per communication step."""
    msd = fmu_path("msd")
    return Scenario(
        path=Path("oscillator (benchmarks/overhead.py)"),
        name="oscillator",
        components=(
            Component("mass1", msd, {"solver": 4, "x0": 1.0}, 1, order, interpolate),
            Component("mass2", msd, {"solver": 4, "cc": 1.0, "dc": 1.0}, 1, order, interpolate),
        ),
        connections=(
            Connection("mass2", "F_c", "mass1", "F"),
            Connection("mass1", "x", "mass2", "x_in"),
            Connection("mass1", "v", "mass2", "v_in"),
        ),
        start_time=Fraction(0),
        stop_time=stop,
        macro_step=H,
    )


def overhead(repeats: int = 3) -> None:
    print(f"{'case':<42} {'macro steps':>11} {'wall s':>8} {'in FMUs s':>9} {'overhead us':>11} {'RTF':>8}")
    for order, interp in ((0, False), (2, False), (2, True)):
        best = None
        for _ in range(repeats):
            s = api.run(oscillator(Fraction(1, 1000), Fraction(10), order, interp)).summary
            best = s if best is None or s.wall_time < best.wall_time else best
        case = f"oscillator H=1ms order {order}{' polynomials to FMU' if interp else ''}"
        print(
            f"{case:<42} {best.macro_steps:>11} {best.wall_time:>8.3f} {sum(best.fmu_time.values()):>9.3f} "
            f"{best.overhead_per_macro_step * 1e6:>11.1f} {best.real_time_factor:>8.1f}"
        )


CHILD = (
    "import resource, sys; from fractions import Fraction; sys.path.insert(0, sys.argv[3]); "
    "import overhead, master.api as api; "
    "api.run(overhead.oscillator(Fraction(1, int(sys.argv[1])), Fraction(1), 0, False), output=sys.argv[2]); "
    "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
)


def memory() -> None:
    fmu_path("msd")
    here = str(Path(__file__).parent)
    with tempfile.TemporaryDirectory() as d:
        peaks = {}
        for n in (10**3, 10**6):
            out = Path(d) / f"{n}.csv"
            r = subprocess.run(
                [sys.executable, "-c", CHILD, str(n), str(out), here], capture_output=True, text=True
            )
            if r.returncode:
                sys.exit(r.stderr)
            peaks[n] = int(r.stdout.split()[-1]) / 1024
            rows = sum(1 for _ in open(out)) - 1
            print(f"{n:>8} macro steps: {rows} rows written, peak RSS {peaks[n]:.1f} MB")
        print(f"difference: {peaks[10**6] - peaks[10**3]:.1f} MB (limit 50 MB)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--memory", action="store_true", help="peak memory of a 10^6-step run vs 10^3")
    args = p.parse_args()
    memory() if args.memory else overhead()


if __name__ == "__main__":
    main()
