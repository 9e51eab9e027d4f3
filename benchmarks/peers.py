"""The same case on two C++ co-simulation masters: libcosim (libcosimpy) and Ecos (ecospy).

    .venv/bin/pip install libcosimpy ecospy tbb && .venv/bin/python benchmarks/peers.py

A case is a plain dict: "components" (name, fmu, step, parameters {var: (type, value)}), "connections"
(source comp, output, consumer comp, input; Real), "inputs" (comp, var, constant Real), "macro_step",
"stop" (s).  Both peers run every component at its own step: base step = gcd of the component steps,
a component stepped every step/base base steps (libcosim: the OSP config's per-simulator stepSize;
Ecos: the model's step size hint); Jacobi, zero-order hold (libcosim passes values when both ends have
finished a step, here every macro step; Ecos after every base step).  Both ignore FMI 2.0 Enumeration
variables, so each FMU is copied with them declared Integer (same binary: FMI 2.0 sets enumerations
through fmi2SetInteger).  Only the stepping is timed (time.perf_counter); with `whole`, the whole run
from loading the FMUs to freeing them (the copies made for Enumerations not counted).
"""

from __future__ import annotations

import ctypes
import importlib
import math
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

NS = 1_000_000_000  # libcosim counts time in ns; steps are checked there to be whole ns


def _import(peer: str) -> None:
    if peer == "ecos":  # ecospy's library needs libtbb.so.12: from `pip install tbb` (or Debian's libtbb12)
        tbb = Path(sys.prefix, "lib", "libtbb.so.12")
        if tbb.exists():
            ctypes.CDLL(str(tbb), mode=ctypes.RTLD_GLOBAL)
    importlib.import_module({"libcosim": "libcosimpy.CosimExecution", "ecos": "ecospy"}[peer])


def available() -> dict[str, str | None]:
    """Per peer: None if it can run, else why not."""
    out: dict[str, str | None] = {}
    for peer in ("libcosim", "ecos"):
        try:
            _import(peer)
            out[peer] = None
        except Exception as e:  # ImportError, or OSError from a bundled shared library
            out[peer] = f"not usable: {e} (pip install libcosimpy ecospy tbb)"
    return out


def _schedule(case: dict) -> tuple[int, int, int]:
    """(base step in ns, base steps in the run, base steps in the first macro step)."""
    steps = [round(c["step"] * NS) for c in case["components"]]
    macro, stop = round(case["macro_step"] * NS), round(case["stop"] * NS)
    base = math.gcd(*steps)
    if min(steps) <= 0 or macro % base or stop % base or any(macro % s for s in steps):
        raise ValueError(f"steps {steps} ns must divide the macro step {macro} ns and the stop {stop} ns")
    return base, stop // base, macro // base


def _prepare(case: dict, tmp: Path) -> dict[str, tuple[Path, str]]:
    """Per component: its FMU copied into tmp, Enumeration variables as Integer; an output to probe."""
    sources = {a: o for a, o, _, _ in reversed(case["connections"])}  # first connected output of each
    out = {}
    for c in case["components"]:
        dst = tmp / f"{c['name']}.fmu"
        with zipfile.ZipFile(c["fmu"]) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
            root = ET.fromstring(zin.read("modelDescription.xml"))
            for sv in root.iter("ScalarVariable"):
                for t in sv.findall("Enumeration"):
                    t.tag = "Integer"
                    t.attrib.pop("declaredType", None)
            md = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
            for item in zin.infolist():
                zout.writestr(item, md if item.filename == "modelDescription.xml" else zin.read(item))
        names = {sv.get("name"): sv.get("causality") for sv in root.iter("ScalarVariable")}
        missing = [v for comp, v, _, _ in _values(case) if comp == c["name"] and v not in names]
        if missing:  # Ecos would only log a warning
            raise ValueError(f"{c['fmu']}: no variable {', '.join(missing)} (component {c['name']})")
        out[c["name"]] = (dst, sources.get(c["name"]) or next(n for n, k in names.items() if k == "output"))
    return out


def _values(case: dict) -> list[tuple[str, str, str, object]]:
    """(component, variable, type, value) of the parameters and constant inputs, set before initialising."""
    vals = [(c["name"], v, t, x) for c in case["components"] for v, (t, x) in c["parameters"].items()]
    return vals + [(comp, var, "Real", float(x)) for comp, var, x in case["inputs"]]


def _osp_config(case: dict, base: int) -> str:
    """libcosim's OspSystemStructure.xml for the case: FMUs as {name}.fmu beside it."""
    q, ns = quoteattr, "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
    xml = [f'<OspSystemStructure xmlns="{ns}" version="0.1"><BaseStepSize>{base / NS!r}</BaseStepSize>']
    xml += ["<Algorithm>fixedStep</Algorithm><Simulators>"]
    for c in case["components"]:
        name = c["name"]
        xml += [f'<Simulator name={q(name)} source="{name}.fmu" stepSize="{c["step"]!r}"><InitialValues>']
        for t, var, x in ((t, var, x) for comp, var, t, x in _values(case) if comp == name):
            t = t if t in ("Real", "Boolean") else "Integer"  # Enumeration: as Integer
            text = str(bool(x)).lower() if t == "Boolean" else repr(int(x) if t == "Integer" else float(x))
            xml += [f'<InitialValue variable={q(var)}><{t} value="{text}"/></InitialValue>']
        xml += ["</InitialValues></Simulator>"]
    xml += ["</Simulators><Connections>"]
    for a, o, b, i in case["connections"]:
        xml += [f"<VariableConnection><Variable simulator={q(a)} name={q(o)}/>"]
        xml += [f"<Variable simulator={q(b)} name={q(i)}/></VariableConnection>"]
    return "\n".join(xml + ["</Connections></OspSystemStructure>"])


def _libcosim(case: dict, probe: bool, whole: bool = False) -> tuple[float, dict[str, float]]:
    from libcosimpy._internal import get_last_error_message
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    base, n, first = _schedule(case)
    if n <= first:
        raise ValueError("libcosim: the run must be longer than one macro step (the first is not timed)")
    with tempfile.TemporaryDirectory(prefix="peer-libcosim-") as tmp:
        fmus = _prepare(case, Path(tmp))
        (Path(tmp) / "OspSystemStructure.xml").write_text(_osp_config(case, base))
        t_load = time.perf_counter()
        try:
            ex = CosimExecution.from_osp_config_file(str(Path(tmp) / "OspSystemStructure.xml"))
        except AssertionError as e:
            raise RuntimeError(f"libcosim could not load the case: {e}") from None
        obs = CosimObserver.create_last_value()
        if probe:
            ex.add_observer(obs)
        # libcosim initialises the FMUs inside its first step: the first macro step runs before the clock
        if not ex.step(first):
            raise RuntimeError(f"libcosim failed in the first macro step: {get_last_error_message()}")
        t0 = time.perf_counter()
        ok = ex.step(n - first)
        wall = (time.perf_counter() - t0) * n / (n - first)
        if not ok or ex.status().current_time != n * base:
            t = ex.status().current_time / NS
            raise RuntimeError(f"libcosim failed in the step from t = {t} s: {get_last_error_message()}")
        values = {}
        for name, (_, var) in fmus.items() if probe else ():
            idx = ex.slave_index_from_instance_name(name)
            vr = next(v.reference for v in ex.slave_variables(idx) if v.name.decode() == var)
            values[f"{name}.{var}"] = obs.last_real_values(idx, [vr])[0]
        del ex
        if whole:
            wall = time.perf_counter() - t_load
    return wall, values


def _ecos(case: dict, probe: bool, whole: bool = False) -> tuple[float, dict[str, float]]:
    _import("ecos")
    from ecospy import EcosLib, EcosSimulation, EcosSimulationStructure
    from ecospy.EcosParameterSet import EcosParameterSet

    EcosLib.set_log_level("warn")
    base, n, _ = _schedule(case)
    with tempfile.TemporaryDirectory(prefix="peer-ecos-") as tmp:
        fmus = _prepare(case, Path(tmp))
        t_load = time.perf_counter()
        try:
            ss, ps = EcosSimulationStructure(), EcosParameterSet()
            for c in case["components"]:
                # decimation = ceil(hint / base): a hint a hair under k base steps gives exactly k
                k = round(c["step"] * NS) // base
                ss.add_model(c["name"], str(fmus[c["name"]][0]), (k - 1e-6) * base / NS)
            for comp, var, t, x in _values(case):
                add = {"Real": ps.add_real, "Boolean": ps.add_bool}.get(t, ps.add_int)
                add(f"{comp}::{var}", x)
            ss.add_parameter_set("case", ps)
            for a, o, b, i in case["connections"]:
                ss.make_real_connection(f"{a}::{o}", f"{b}::{i}")
            sim = EcosSimulation(step_size=base / NS, structure=ss)
        except Exception as e:
            raise RuntimeError(f"Ecos could not load the case: {e}") from None
        if not sim.init(0.0, "case"):
            raise RuntimeError(f"Ecos could not initialise: {EcosLib.get_last_error()}")
        t0 = time.perf_counter()
        t_end = sim.step(n)  # Ecos ignores an FMU's failed fmi2DoStep: check() tells whether it moved
        wall = time.perf_counter() - t0
        if not math.isclose(t_end, n * base / NS, rel_tol=1e-9):
            raise RuntimeError(f"Ecos stopped at t = {t_end} s instead of {n * base / NS} s")
        values = {f"{name}.{var}": sim.get_real(f"{name}::{var}") for name, (_, var) in fmus.items()}
        sim.terminate()
        sim.free()
        if whole:
            wall = time.perf_counter() - t_load
    return wall, values


def run_libcosim(case: dict, whole: bool = False) -> float:
    """Wall seconds of libcosim stepping the case from 0 to stop (the first macro step, inside which
    libcosim initialises the FMUs, runs before the clock; the rest is scaled to the whole run).
    whole: of the whole run instead, as a user sees it: loading the FMUs to freeing them."""
    return _libcosim(case, probe=False, whole=whole)[0]


def run_ecos(case: dict, whole: bool = False) -> float:
    """Wall seconds of Ecos stepping the case from 0 to stop (initialised before the clock).  Ecos does
    not report an FMU's failed fmi2DoStep (it steps on): check() shows whether the outputs moved.
    whole: of the whole run instead, as a user sees it: loading the FMUs to freeing them."""
    return _ecos(case, probe=False, whole=whole)[0]


def check(case: dict) -> dict[str, dict[str, float] | str]:
    """Per peer: the final value of one output per component ("comp.var"; the first output it feeds
    into a connection), or why the peer could not run; to see that it really simulated."""
    out: dict[str, dict[str, float] | str] = {}
    for peer, why in available().items():
        try:
            out[peer] = why or {"libcosim": _libcosim, "ecos": _ecos}[peer](case, True)[1]
        except Exception as e:
            out[peer] = f"{type(e).__name__}: {e}"
    return out


def case_of(sc) -> dict:
    """The case of a master.scenario Scenario (stimuli held at their last value)."""
    from master.api import plan
    from master.description import variables_of
    from master.fmu import read_description

    comps = []
    for pc in plan(sc).components:
        c = sc.component(pc.name)
        var = variables_of(read_description(c.fmu_path))
        kind = {n: var[n].type if var[n].type in ("Real", "Boolean") else "Integer" for n in c.parameters}
        params = {n: (kind[n], v) for n, v in c.parameters.items()}
        comps.append({"name": pc.name, "fmu": str(c.fmu_path), "step": float(pc.step), "parameters": params})
    conns = [(c.start_component, c.start_connector, c.end_component, c.end_connector) for c in sc.connections]
    inputs = [(s.component, s.variable, float(s.values[-1])) for s in sc.stimuli]
    return {"components": comps, "connections": conns, "inputs": inputs,
            "macro_step": float(sc.macro_step), "stop": float(sc.stop_time)}  # fmt: skip


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import master.api as api
    from master.evidence.oscillator import scene

    print("peers:", {k: v or "ok" for k, v in available().items()})
    ssd = Path(__file__).resolve().parents[1] / "models/hydraulic-manipulator/SystemStructure.ssd"
    for label, sc in (("oscillator, 10 s", scene()), ("hydraulic manipulator, 3 s", api.load_scenario(ssd))):
        case = case_of(sc)
        probes = check(case)
        record = sorted({k for v in probes.values() if isinstance(v, dict) for k in v})
        res = api.run(sc, backend="in-process", record=record)
        s, nan = res.summary, float("nan")
        print(f"\n{label}: steps {[c['step'] for c in case['components']]} s")
        t = getattr(s, "stepping_time", nan) * 1e3  # stepping_time: newer master.recorder
        print(f"  ours     stepping {t:7.1f} ms, wall {s.wall_time * 1e3:.1f} ms (in-process)")
        print(f"           final {', '.join(f'{k} = {res.data[k][-1]:.6g}' for k in record)}")
        for peer, run in (("libcosim", run_libcosim), ("ecos", run_ecos)):
            if isinstance(probes[peer], str):
                print(f"  {peer:<8} failed: {probes[peer]}")
                continue
            print(f"  {peer:<8} stepping {min(run(case) for _ in range(3)) * 1e3:7.1f} ms (best of 3)")
            print(f"           final {', '.join(f'{k} = {v:.6g}' for k, v in probes[peer].items())}")
