"""The master against the physical limit and against C++ masters, side by side in one run.

    .venv/bin/python benchmarks/native.py [--repeat N] [--no-peers] [--whole]

Cases: (a) the hydraulic-manipulator scene at the paper's steps (mechanics 1e-3 s, hydraulics
2e-4 s, 3 s); (b) the same with both FMUs at 2e-4 s; (c) the two-mass oscillator at 1e-2 s for 10 s.
Each case runs, interleaved `--repeat` times (best and median printed), on:
  harness      benchmarks/harness.c: dlopens the same FMUs and makes the same FMI calls in the
               same schedule with no master at all (order-0 coupling; no polynomials, no checks),
               without the re-read of outputs that depend on inputs at each macro step's end
  equal-work   the harness with that re-read (--equal-work: the calls the master's semantics
               needs, kernel.h resampling); the ratios are against it
  in-process   the kernel in this process
  serial       the kernel in one worker process (the default for one group)
  parallel     one worker per component, dataflow synchronisation
  libcosim, ecos   the C++ masters through libcosimpy and ecospy (`pip install -e '.[peers]'`),
               each at its components' own steps, skipped with a note when not installed
Times are of the stepping alone (FMUs loaded and initialised before the clock starts). Printed:
each time and its ratio to the equal-work harness, and the peers' times over serial (> 1: we are
faster). --whole: times of whole runs instead, as a user sees them (ours: `master.run` of the
Scenario, planning, loading, initialisation, stepping and closing; the peers': loading the FMUs to
freeing them), without the harness.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.backends.component import output_names, samples_read
from master.description import feedthrough_outputs, variables_of
from master.evidence.oscillator import scene as oscillator_scene
from master.fmu import read_description, safe_extract
from master.runtime.tables import resampling
from master.scenario.model import Scenario

REPO = Path(__file__).resolve().parent.parent
HARNESS_C = Path(__file__).resolve().parent / "harness.c"
HYDRAULIC = REPO / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"
BACKENDS = ("in-process", "serial", "parallel")


def cases() -> dict[str, Scenario]:
    hydraulic = api.load_scenario(HYDRAULIC)
    single = dataclasses.replace(
        hydraulic,
        macro_step=Fraction(1, 5000),
        components=tuple(dataclasses.replace(c, step_ratio=1) for c in hydraulic.components),
    )
    osc = oscillator_scene(split="force", macro_step=Fraction(1, 100), stop_time=Fraction(10), order=2)
    return {
        "(a) hydraulic, paper steps": hydraulic,
        "(b) hydraulic, both 2e-4 s": single,
        "(c) oscillator": osc,
    }


def build_harness(out_dir: Path) -> Path:
    exe = out_dir / "harness"
    cc = os.environ.get("CC") or shutil.which("cc") or "gcc"
    subprocess.run([cc, "-O2", "-std=c99", "-o", str(exe), str(HARNESS_C), "-ldl"], check=True)
    return exe


def harness_schedule(sc: Scenario, work: Path) -> Path:
    """The harness's schedule file for `sc` (FMUs extracted under `work`)."""
    p = api.plan(sc)
    names = [pc.name for pc in p.components]
    variables = {c.name: variables_of(read_description(c.fmu_path)) for c in sc.components}
    outs = {n: output_names(p, n, variables[n]) for n in names}
    lines = [f"macro {p.n_macro} {float(sc.macro_step)!r} {len(names)}"]
    for pc in p.components:
        comp = sc.component(pc.name)
        md = read_description(comp.fmu_path)
        folder = safe_extract(comp.fmu_path, work / pc.name)
        lib = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        var = variables[pc.name]
        params = []
        for name, value in comp.parameters.items():
            kind = {"Real": "R", "Boolean": "B"}.get(var[name].type, "I")
            params.append(f"{kind} {var[name].vr} {float(value)!r}")
        inputs = []
        for lk in p.links_into(pc.name):
            for o, i in zip(lk.outputs, lk.inputs, strict=True):
                inputs.append(f"{var[i].vr} {names.index(lk.source)} {outs[lk.source].index(o)}")
        for s in p.stimuli:
            if s.component == pc.name:
                inputs.append(f"{var[s.variable].vr} -1 {float(s.values[-1])!r}")
        reads = " ".join(str(int(r)) for r in samples_read(p, pc.name))
        feedthrough = int(bool(inputs) and bool(feedthrough_outputs(md) & set(outs[pc.name])))
        out_vrs = " ".join(str(var[o].vr) for o in outs[pc.name])
        lines.append(
            f"component {lib} {md.guid} {(folder / 'resources').as_uri()} {pc.name} {pc.step_ratio} "
            f"{float(pc.step)!r} {feedthrough} {len(params)} {len(inputs)} {len(outs[pc.name])}"
        )
        lines += params + inputs + [f"{out_vrs} {reads}"]
    _, order = resampling(p, outs)
    assert all(isinstance(e, str) for e in order), "the harness does not solve algebraic loops"
    lines.append(f"resample {len(order)} " + " ".join(str(names.index(e)) for e in order))
    path = work / "schedule.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def peer_case(sc: Scenario) -> dict:
    """The case description benchmarks/peers.py runs."""
    p = api.plan(sc)
    comps = []
    for pc in p.components:
        c = sc.component(pc.name)
        var = variables_of(read_description(c.fmu_path))
        kinds = {"Real": "Real", "Boolean": "Boolean"}
        params = {n: (kinds.get(var[n].type, "Integer"), v) for n, v in c.parameters.items()}
        comps.append({"name": pc.name, "fmu": str(c.fmu_path), "step": float(pc.step), "parameters": params})
    return {
        "components": comps,
        "connections": [
            (c.start_component, c.start_connector, c.end_component, c.end_connector) for c in sc.connections
        ],
        "inputs": [(s.component, s.variable, float(s.values[-1])) for s in sc.stimuli],
        "macro_step": float(sc.macro_step),
        "stop": float(sc.stop_time),
    }


def peers() -> tuple[dict, list[str]]:
    """Runner per installed peer, and a note per missing one."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    try:
        import peers as pe
    except ImportError as e:
        return {}, [f"peers: {e}"]
    runners, notes = {}, []
    for name, why in pe.available().items():
        if why is None:
            runners[name] = getattr(pe, f"run_{name}")
        else:
            notes.append(f"{name}: skipped ({why})")
    return runners, notes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--whole", action="store_true", help="time whole runs, initialisation included")
    ap.add_argument("--cases", default="abc", help="which cases, e.g. c (default: abc)")
    args = ap.parse_args(argv)
    runners, notes = ({}, ["peers: not asked for"]) if args.no_peers else peers()
    what = "whole runs" if args.whole else "stepping alone"
    print(f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; {what}, {args.repeat} interleaved runs")
    for note in notes:
        print(note)
    with tempfile.TemporaryDirectory(prefix="bench-native-") as tmp:
        exe = build_harness(Path(tmp))
        for label, sc in cases().items():
            if label[1] not in args.cases:
                continue
            work = Path(tmp) / label.split()[0].strip("()")
            work.mkdir()
            schedule = harness_schedule(sc, work)
            case = peer_case(sc)
            times: dict[str, list[float]] = {}
            for _ in range(args.repeat):
                for name, extra in (("harness", []), ("equal-work", ["--equal-work"])) * (not args.whole):
                    cmd = [str(exe), str(schedule), *extra]
                    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
                    times.setdefault(name, []).append(float(out.stdout))
                for be in BACKENDS:
                    t0 = time.perf_counter()
                    t = api.run(sc, backend=be).summary.stepping_time
                    times.setdefault(be, []).append(time.perf_counter() - t0 if args.whole else t)
                for name, run in runners.items():
                    try:
                        times.setdefault(name, []).append(run(case, whole=args.whole))
                    except Exception as e:  # a peer that cannot run this case is reported, not fatal
                        notes.append(f"{name} on {label}: {e}")
                        runners = {k: v for k, v in runners.items() if k != name}
            best = {name: min(ts) for name, ts in times.items()}
            median = {name: statistics.median(ts) for name, ts in times.items()}
            print(f"\n{label}: {api.plan(sc).n_macro} macro steps (load {os.getloadavg()[0]:.2f})")
            for name, t in best.items():
                ratio = "" if args.whole else f"   {t / best['equal-work']:5.2f} x equal-work harness"
                print(f"  {name:<11} best {t * 1e3:8.2f} ms, median {median[name] * 1e3:8.2f} ms{ratio}")
            for name in runners:
                if name in best:
                    print(
                        f"  {name} / serial = {best[name] / best['serial']:.2f} on best times, "
                        f"{median[name] / median['serial']:.2f} on medians"
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
