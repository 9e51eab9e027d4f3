"""String connections, FMI 2.0 and 3.0: held between communication points (kernel.h: MK_STRING_SLOT).

Real FMUs throughout: the project's text FMU (fmus/text/model.c, built as FMI 2.0 and as FMI 3.0):
y_string = u_string followed by `repeat` copies of `suffix`, y_length and y_code the byte count and
a checksum of u_string (Integers), y = u; and
the FMI 3.0 FMU alltypes, y_string = u_string + "!". The expected values are computed here from
those rules and from the documented coupling, the held sample of each consumer step (the first
source sample at or after the step's end that exists: up to t_n in Jacobi, t_n+1 where the source
goes first), not with the master's code.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.backends.component import output_names
from master.description import variables_of
from master.fmu import read_description
from master.fmubuild import fmu_path
from master.runtime import native
from master.runtime.tables import layout
from master.scenario import validate
from master.scenario.model import Component, Connection, Scenario, Stimulus

H = Fraction(1, 10)
STOP = Fraction(2)
N = int(STOP / H)
CAPACITY = 2047  # bytes a String of the test FMUs holds (fmus/fmi/model.h: STRING_CAPACITY - 1)
# a.repeat: steps between communication points; a's String output changes with it
TIMES, REPEATS = (0.25, 0.85, 1.35), (3.0, 0.0, 2.0)
A = {"suffix": "ab", "u_string": "x"}  # a's suffix and the start value of its String input


def text(fmi: int = 2) -> Path:
    return fmu_path("text", fmi=fmi)


def alltypes() -> Path:
    return fmu_path("alltypes", fmi=3)


def text_rule(u: bytes, repeat: int, suffix: bytes) -> bytes:
    """text's y_string for input u, `repeat` and parameter `suffix` (bytes, as the FMU sees them)."""
    return (u + suffix * max(repeat, 0))[:CAPACITY]


def alltypes_rule(u: bytes) -> bytes:
    return (u + b"!")[:CAPACITY]


def length_and_code(u: bytes) -> tuple[int, int]:
    """text's y_length and y_code of input u."""
    return len(u), sum((i + 1) * b for i, b in enumerate(u)) % 1000003


def repeat_at(t: Fraction) -> int:
    """a.repeat at time t: the step stimulus (1, the start value, before its first time)."""
    value = 1
    for at, v in zip(TIMES, REPEATS, strict=True):
        if t >= Fraction(str(at)):
            value = int(v)
    return value


def held(n: int, m: int, k_source: int, k_consumer: int, ahead: bool) -> int:
    """The source sample a held connection hands to the consumer's step m of macro step n: the first
    at or after the step's end, but none later than the source has produced (t_n in Jacobi, t_n+1
    where the source goes first)."""
    j = n * k_consumer + m
    return min((n + 1 if ahead else n) * k_source, -(-(j + 1) * k_source // k_consumer))


def source_samples(k: int) -> list[bytes]:
    """a's y_string at its communication points (a sets its step-end inputs: repeat at t_j)."""
    return [text_rule(b"x", repeat_at(j * H / k), b"ab") for j in range(N * k + 1)]


def consumer_samples(source: list[bytes], ks: int, kc: int, ahead, rule) -> list[bytes]:
    """A consumer's String output at its communication points: `rule` of the held input of the
    step ending there, but at a macro step's end of the source's sample there, set again before the
    output is read again (resampling: the output depends on the input); the initial sweep: of the
    source's sample 0. ahead(n): whether the source is ahead in macro step n."""
    out = [rule(source[0])]
    for n in range(N):
        out += [rule(source[held(n, m, ks, kc, ahead(n))]) for m in range(kc - 1)]
        out.append(rule(source[(n + 1) * ks]))
    return out


def row_inputs(source: list[bytes], ks: int) -> list[bytes]:
    """A consumer's String input at each row: the source's sample at the row's time (resampling)."""
    return [source[n * ks] for n in range(N + 1)]


def check_rows(d: np.ndarray, component: str, inputs: list[bytes]) -> None:
    expected = np.array([length_and_code(u) for u in inputs], dtype=float)
    assert np.array_equal(d[f"{component}.y_length"], expected[:, 0]), component
    assert np.array_equal(d[f"{component}.y_code"], expected[:, 1]), component


def scenario(comps, conns, coupling: str, stimuli=(), record=()) -> Scenario:
    order = tuple(c.name for c in comps) if coupling == "gauss-seidel" else ()
    stimuli = (Stimulus("a", "repeat", "step", TIMES, REPEATS), *stimuli)
    return Scenario(Path("strings.ssd"), "strings", tuple(comps), tuple(conns), Fraction(0), STOP, H,
                    coupling=coupling, order=order, stimuli=stimuli, record=tuple(record))  # fmt: skip


@pytest.mark.parametrize(
    "coupling, ka, kb, kc",
    [("jacobi", 1, 3, 1), ("jacobi", 3, 1, 2), ("gauss-seidel", 1, 3, 1), ("gauss-seidel", 3, 1, 2)],
)
def test_fmi2_strings_are_held_along_a_chain(coupling, ka, kb, kc):
    """a -> b -> c, text FMI 2.0 throughout: b holds a's sample of each step, c b's; b appends a
    two-byte UTF-8 character, bytes travel unchanged."""
    fmu = text()
    comps = (Component("a", fmu, dict(A), ka), Component("b", fmu, {"suffix": "é"}, kb))
    comps += (Component("c", fmu, {}, kc),)
    conns = (Connection("a", "y_string", "b", "u_string"), Connection("b", "y_string", "c", "u_string"))
    record = [(c, v) for c in "bc" for v in ("y_length", "y_code")]
    sc = scenario(comps, conns, coupling, record=record)
    plan = api.plan(sc)
    assert {(lk.kind, lk.order) for lk in plan.links} == {("String", 0)}
    assert "a.y_string -> b.u_string: order 0, held (String)" in plan.describe()
    d = run_everywhere(sc)
    assert len(d) == N + 1

    def ahead(n: int) -> bool:
        return coupling == "gauss-seidel"

    a = source_samples(ka)
    b = consumer_samples(a, ka, kb, ahead, lambda u: text_rule(u, 1, "é".encode()))
    check_rows(d, "b", row_inputs(a, ka))
    check_rows(d, "c", row_inputs(b, kb))
    assert {len(u) for u in row_inputs(b, kb)} == {3, 5, 7, 9}  # a's 1, 3, 5 or 7 bytes, é
    assert list(d["b.y_length"]) == [len(a[n * ka]) for n in range(N + 1)]  # a's sample at the row


@pytest.mark.parametrize("fmi", [3, 2])
@pytest.mark.parametrize("coupling", ["jacobi", "gauss-seidel"])
def test_fmi3_strings_and_across_versions(fmi, coupling):
    """a -> b -> c with b alltypes (FMI 3.0, fmi3GetString / fmi3SetString) stepping 3 times per
    macro step, a and c text as FMI 3.0 or, across versions, as FMI 2.0 (FMI 2 String -> FMI 3
    String -> FMI 2 String)."""
    comps = (Component("a", text(fmi), dict(A)), Component("b", alltypes(), {}, 3), Component("c", text(fmi)))
    conns = (Connection("a", "y_string", "b", "u_string"), Connection("b", "y_string", "c", "u_string"))
    sc = scenario(comps, conns, coupling, record=[("c", "y_length"), ("c", "y_code")])
    assert read_description(text(fmi)).fmiVersion == f"{fmi}.0"
    d = run_everywhere(sc)

    def ahead(n: int) -> bool:
        return coupling == "gauss-seidel"

    a = source_samples(1)
    b = consumer_samples(a, 1, 3, ahead, alltypes_rule)
    check_rows(d, "c", row_inputs(b, 3))
    assert set(d["c.y_length"]) == {2, 4, 6, 8}  # a's 1, 3, 5 or 7 bytes and "!"


def test_a_resampled_consumer_sets_its_string_inputs_again_and_keeps_its_string_outputs():
    """Resampling (kernel.h): b's outputs depend on its inputs, so after each macro step b's linked
    inputs are set again to a's samples at its end, the String input too (as an Integer one), and
    its outputs are read again, the String one too: c, which b's String drives, gets b's sample of
    a's sample at the macro step's end. b extrapolates u with order 2, so the first macro steps are repeated
    (start-up sweeps, in which a counts as ahead and the previous sweep's String samples are read)."""
    fmu = text()
    comps = (Component("a", fmu, dict(A)), Component("b", fmu, {"suffix": "é"}, 2, 2), Component("c", fmu))
    conns = (Connection("a", "y", "b", "u"), Connection("a", "y_string", "b", "u_string"),
             Connection("b", "y_string", "c", "u_string"))  # fmt: skip
    record = [("b", "y"), ("b", "y_length"), ("b", "y_code"), ("c", "y_length"), ("c", "y_code")]
    sc = scenario(comps, conns, "jacobi", (Stimulus("a", "u", "table", (0.0, 2.0), (0.0, 1.0)),), record)
    plan = api.plan(sc)
    assert plan.startup_steps > 0 and plan.startup_sweeps > 0
    d = run_everywhere(sc)

    def ahead(n: int) -> bool:
        return n < plan.startup_steps  # the relaxed sweeps of start-up read a's samples up to t_n+1

    a = source_samples(1)
    b = consumer_samples(a, 1, 2, ahead, lambda u: text_rule(u, 1, "é".encode()))
    check_rows(d, "b", a[: N + 1])  # set again: a's sample at the row, not the held one
    check_rows(d, "c", row_inputs(b, 2))
    stepped = [a[0]] + [a[held(n, 1, 1, 2, ahead(n))] for n in range(N)]  # what b's last step was given
    assert sum(u != v for u, v in zip(stepped, a, strict=False)) == 3  # a changed inside 3 macro steps
    assert np.array_equal(d["b.y"], d["time"] / 2.0)  # read again: a.y = a.u at the row


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_string_longer_than_a_slot_stops_the_run(backend):
    """a.y_string = 6 copies of a 200-byte suffix from t = 0.6 on: 1200 bytes, more than the 1023 a
    String connection carries. The rows before it are kept."""
    fmu = text()
    comps = (Component("a", fmu, {"suffix": "abcdefghij" * 20}), Component("b", fmu))
    link = (Connection("a", "y_string", "b", "u_string"),)
    stimuli = (Stimulus("a", "repeat", "step", (0.55,), (6.0,)),)
    sc = Scenario(Path("long.ssd"), "long", comps, link, Fraction(0), Fraction(1), H, stimuli=stimuli,
                  record=(("b", "y_length"),))  # fmt: skip
    message = "a.y_string is 1200 bytes long at t=0.6: a String connection carries at most 1023 bytes"
    with pytest.raises(api.SimulationError) as failed:
        api.run(sc, backend=backend)
    assert str(failed.value) == message
    assert (failed.value.component, failed.value.variable, failed.value.time) == ("a", "y_string", 0.6)
    assert list(failed.value.result.data["b.y_length"]) == [200.0] * 6  # t = 0 .. 0.5
    # already too long at the start time: the initial sweep stops it
    start = {"u_string": "z" * 900, "suffix": "0123456789" * 20}
    comps = (Component("a", fmu, start), Component("b", fmu))
    sc = Scenario(Path("long.ssd"), "long", comps, link, Fraction(0), Fraction(1), H)
    with pytest.raises(api.SimulationError, match=r"^a\.y_string is 1100 bytes long at t=0\.0: "):
        api.run(sc, backend=backend)


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A folder holding text.fmu (FMI 2.0) and alltypes.fmu (FMI 3.0) for scenario files to name."""
    shutil.copy(text(), tmp_path / "text.fmu")
    shutil.copy(alltypes(), tmp_path / "alltypes.fmu")
    return tmp_path


def test_the_command_line_stops_a_too_long_string_with_one_line(folder: Path):
    stimulus = '<mm:Stimuli><mm:Step component="a" variable="repeat"><mm:Point time="0.55" value="6"/>'
    stimulus += "</mm:Step></mm:Stimuli>"
    path = ssd(folder / "long.ssd", {"a": "text.fmu", "b": "text.fmu"}, [("a", "y_string", "b", "u_string")],
               stimulus)  # fmt: skip
    assert validate(path) == []
    command = [sys.executable, "-m", "master", "run", str(path), "-o", str(folder / "out.csv"),
               "--set", f"a.suffix={'abcdefghij' * 20}"]  # fmt: skip
    run = subprocess.run([*command, "-q"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        "error: a.y_string is 1200 bytes long at t=0.6: a String connection carries at most 1023 bytes"
    ]
    loud = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert loud.returncode == 1 and "Traceback" not in loud.stderr and "1200 bytes long" in loud.stderr


def test_validate_accepts_string_to_string_and_refuses_string_to_a_number(folder: Path):
    good = ssd(folder / "good.ssd", {"a": "text.fmu", "b": "text.fmu", "t": "alltypes.fmu"},
               [("a", "y_string", "b", "u_string"), ("b", "y_string", "t", "u_string")])  # fmt: skip
    assert validate(good) == []  # FMI 2 String -> FMI 2 String -> FMI 3 String
    command = [sys.executable, "-m", "master", "validate"]
    run = subprocess.run([*command, str(good)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    d = api.run(good, backend="in-process").data  # every recordable output, the Strings too
    assert d["b.y_length"][-1] == 1 and d["b.y_code"][-1] == ord("!")  # a's u_string is "" (its start)
    assert (d["a.y_string"][-1], d["b.y_string"][-1], d["t.y_string"][-1]) == ("!", "!!", "!!!")

    settings = (
        '<mm:Stimuli><mm:Step component="a" variable="u_string"><mm:Point time="0" value="1"/></mm:Step>'
        "</mm:Stimuli>"
    )
    bad = ssd(folder / "bad.ssd", {"a": "text.fmu", "b": "text.fmu"},
              [("a", "y_string", "b", "repeat"), ("a", "y_length", "b", "u_string")], settings)  # fmt: skip
    assert [(p.element, p.message) for p in validate(bad)] == [
        ("ssd:Connection a.y_string -> b.repeat", "type mismatch: a.y_string is String, b.repeat is Integer"),
        ("ssd:Connection a.y_length -> b.u_string",
         "type mismatch: a.y_length is Integer, b.u_string is String"),
        ("mm:Step a.u_string", "a.u_string is String: stimuli drive numeric, Boolean and Enumeration inputs"),
    ]  # fmt: skip
    run = subprocess.run([*command, str(bad)], capture_output=True, text=True, timeout=120)
    assert run.returncode != 0 and "a.y_string is String, b.repeat is Integer" in run.stdout + run.stderr


def test_only_components_with_string_outputs_on_connections_get_a_string_ring():
    fmu = text()
    comps = (Component("a", fmu, dict(A)), Component("b", fmu), Component("c", fmu))
    conns = (Connection("a", "y_string", "b", "u_string"), Connection("a", "y", "c", "u"))
    plan = api.plan(scenario(comps, conns, "jacobi", record=[("b", "y_length")]))
    variables = variables_of(read_description(fmu))
    outs = {c.name: output_names(plan, c.name, variables) for c in comps}
    rings = {name: shape for name, (shape, _) in layout(plan, outs, 0).items() if name.startswith("strings")}
    slot = native.STRING_SLOT  # a length, up to 1023 bytes, a zero
    assert slot == 1032 and rings == {"strings:a": (3, 1, slot), "strings_previous:a": (3, 1, slot)}
    assert outs == {"a": ["y"], "b": [], "c": []}  # the numeric history holds no String
