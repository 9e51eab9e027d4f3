"""Algebraic loops: iterations and evaluations per solve, Newton with directional derivatives,
Newton with finite differences and Anderson's fixed point, side by side in one run (not a test:
counts are exact, times depend on the machine).

    .venv/bin/python benchmarks/loops.py [--points 1000]

Cases: a ring of an adder and n gains of loop gain -0.5 (linear: Newton needs one step, and one
Jacobian for the whole run), and an adder with a cubic block (a y^3 + 1.5 y = s(t), nonlinear:
the Jacobian is kept while Newton converges fast and refreshed where it slows). Each at every
communication point of a table stimulus s(t), tolerance 1e-12, in-process. Printed per case and
method: solves, iterations per solve (mean, most), Jacobians, member evaluations per solve (each
sets every member's inputs and reads its outputs: the FMI work), the error against the exact
solution, and the wall time per solve.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import master.api as api

SETTINGS = (
    '<mm:Stimuli><mm:Table component="add" variable="u1"><mm:Point time="0" value="1"/>'
    '<mm:Point time="5" value="3"/><mm:Point time="10" value="-2"/></mm:Table></mm:Stimuli>'
)
METHODS = {
    "newton, directional derivatives": 'method="newton"',
    "newton, finite differences": 'method="newton" directionalDerivatives="false"',
    "fixed point (Anderson)": 'method="fixed-point"',
}


def scene(folder: Path, blocks: list[tuple[str, str]], loops: str, points: int) -> Path:
    """add (u1 = s(t), u2 = the last block's y) -> blocks[0] -> ... -> add.u2."""
    names = ["add"] + [n for n, _ in blocks]
    sources = ["blocks_add"] + [s for _, s in blocks]
    chain = list(zip(names, names[1:] + ["add"], strict=True))
    elements = "".join(
        f'<ssd:Component name="{n}" source="{s}"><ssd:Connectors>'
        f'<ssd:Connector name="{"u2" if n == "add" else "u"}" kind="input"/>'
        f'<ssd:Connector name="y" kind="output"/></ssd:Connectors></ssd:Component>'
        for n, s in zip(names, sources, strict=True)
    )
    connections = "".join(
        f'<ssd:Connection startElement="{a}" startConnector="y" endElement="{b}" '
        f'endConnector="{"u2" if b == "add" else "u"}"/>'
        for a, b in chain
    )
    path = folder / f"loop{len(blocks)}.ssd"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="loop"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="loop">
    <ssd:Elements>{elements}</ssd:Elements>
    <ssd:Connections>{connections}</ssd:Connections>
    <ssd:Annotations><ssc:Annotation type="org.multirate-master.settings">
      <mm:Settings macroStep="{10 / points!r}">{SETTINGS}<mm:Loops {loops} tolerance="1e-12"/></mm:Settings>
    </ssc:Annotation></ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="10"/>
</ssd:SystemStructureDescription>
""")
    return path


def stimulus(t: np.ndarray) -> np.ndarray:
    return np.interp(t, [0.0, 5.0, 10.0], [1.0, 3.0, -2.0])


def cubic_root(s: float) -> float:
    roots = np.roots([2.0, 0.0, 1.5, -s])
    return float(roots[np.argmin(abs(roots.imag))].real)


def cases(folder: Path, loops: str, points: int):
    """(name, scenario, exact add.y as a function of the times)."""
    for n in (3, 10):
        k = 0.5 ** (1 / n)
        blocks = [(f"g{i}", "blocks_gain") for i in range(n)]
        values = {f"g{i}.k": repr(-k if i == 0 else k) for i in range(n)}
        sc = api.load_scenario(scene(folder, blocks, loops, points), values)
        yield f"ring of {n} gains, loop gain -0.5", sc, lambda t: stimulus(t) / 1.5
    sc = api.load_scenario(scene(folder, [("c", "cubic")], loops, points), {"c.a": "-2.0", "c.b": "-0.5"})
    yield "cubic: 2 y^3 + 1.5 y = s(t)", sc, lambda t: np.array([cubic_root(s) for s in stimulus(t)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1000, help="communication points over 10 s")
    args = ap.parse_args()
    print(f"{'case':<34} {'method':<33} {'solves':>6} {'it/solve':>8} {'most':>4} {'Jacobians':>9} "
          f"{'evals/solve':>11} {'max error':>9} {'us/solve':>8}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for method, attrs in METHODS.items():
            for name, sc, exact in cases(Path(tmp), attrs, args.points):
                res = api.run(sc, backend="in-process")
                (s,) = res.summary.loops.values()
                error = float(np.max(np.abs(res.data["add.y"] - exact(res.data["time"]))))
                print(
                    f"{name:<34} {method:<33} {s['solves']:>6} {s['iterations'] / s['solves']:>8.2f} "
                    f"{s['most']:>4} {s['jacobians']:>9} {s['evaluations'] / s['solves']:>11.2f} "
                    f"{error:>9.1e} {1e6 * res.summary.stepping_time / s['solves']:>8.1f}"
                )


if __name__ == "__main__":
    main()
