"""The coupling error estimate against the true coupling error, on the two-mass oscillator.

    .venv/bin/python benchmarks/error_estimate.py

For macro steps H = 0.1 ... 0.01 s and extrapolation orders 0-3 (force split, polynomial inputs
handed to both FMUs), on the connection mass1.x -> mass2.x_in, each relative to the range of x
(`master.evidence.oscillator.estimate_against_truth`): est, the run summary's estimate; link, the
true coupling error of the connection (the value mass2 was given against the exact x); x1, the
error the coupling leaves in mass1.x. The ratios est / link and est / x1 follow each.
"""

from fractions import Fraction

from master.evidence.oscillator import estimate_against_truth

STEPS = (Fraction(1, 10), Fraction(1, 20), Fraction(1, 50), Fraction(1, 100))


def main() -> int:
    for h in STEPS:
        cells = []
        for p in range(4):
            est, link, x1 = estimate_against_truth(h, p)
            cells.append(
                f"p{p}: est {est:.1e} link {link:.1e} ({est / link:.2f}) x1 {x1:.1e} ({est / x1:.2f})"
            )
        print(f"H={float(h)}", " | ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
