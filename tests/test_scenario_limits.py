"""Numbers and sizes in a scenario: bounded cost to read, limits checked at validate, one clear
problem each (the classes a mutation campaign over scenario files turned up)."""

import shutil
from pathlib import Path

import pytest

import master.api as api
from master.scenario import ScenarioError

SCENE = Path(__file__).resolve().parent / "scenarios" / "oscillator"


def mutated(tmp_path: Path, old: str, new: str) -> Path:
    """The oscillator scene with `old` replaced by `new` (its parameter files beside it)."""
    for f in SCENE.iterdir():
        shutil.copy(f, tmp_path / f.name)
    ssd = tmp_path / "oscillator.ssd"
    text = ssd.read_text()
    assert old in text
    ssd.write_text(text.replace(old, new, 1))
    return ssd


CASES = [
    ("fraction-time", 'stopTime="10"', 'stopTime="1/0"', "not a decimal number"),
    ("overflowing-stop", 'stopTime="10"', 'stopTime="1e400"', "exponent is beyond"),
    ("overflowing-start", 'startTime="0"', 'startTime="-1e309"', "exponent is beyond"),
    ("huge-exponent", 'stopTime="10"', 'stopTime="1e100000000"', "exponent is beyond"),
    ("too-far", 'stopTime="10"', 'stopTime="1e13"', "is beyond 1e+12 s"),
    ("many-digits-macro", 'macroStep="0.01"', 'macroStep="0.' + "0" * 5000 + '1"', "characters"),
    ("long-step", 'communicationStep="0.0025"', 'communicationStep="0.0025' + "0" * 60 + '"', "characters"),
    ("huge-ratio", 'stepRatio="1"', 'stepRatio="1000000000"', "at most 100000"),
    ("endless-ratio", 'stepRatio="1"', 'stepRatio="' + "9" * 5000 + '"', "at most 100000"),
    ("too-many-steps", 'macroStep="0.01"', 'macroStep="1e-10"', "macro steps from startTime to stopTime"),
    ("inexact-clock", 'macroStep="0.01"', 'macroStep="0.0000000000000000000000000001"', "at most"),
]


@pytest.mark.parametrize("old, new, said", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_numbers_are_one_problem_each(old, new, said, tmp_path):
    """One clear problem each, saying what is wrong (a 1e100000000 once took minutes to refuse;
    the limits on exponents and digits keep that away, a timed bound here would fail under load)."""
    ssd = mutated(tmp_path, old, new)
    problems = api.validate(ssd)
    assert problems, "validate accepted it"
    assert any(said in str(p) for p in problems), [str(p) for p in problems]
    with pytest.raises(ScenarioError):
        api.load_scenario(ssd)


def test_interpolated_inputs_keep_the_communication_step_as_internal_step():
    """mass2 interpolates its inputs with communicationStep 0.0025 s: one doStep per macro step of
    0.01 s, in four internal steps (not one, as the step ratio silently became before)."""
    sc = api.load_scenario(SCENE / "oscillator.ssd")
    m2 = sc.component("mass2")
    assert m2.interpolate_inputs and m2.step_ratio == 4 and m2.parameters["internal_step"] == 0.0025
    assert any("internal step" in note for note in api.plan(sc).notes)


def test_interpolated_inputs_without_an_internal_step_are_refused(tmp_path):
    """An FMU that can interpolate inputs but has no internal_step parameter cannot keep a step
    ratio: validate says so (here msd with that parameter renamed in its model description)."""
    import zipfile

    from master.fmubuild import fmu_path

    src, dst = fmu_path("msd"), tmp_path / "other.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'name="internal_step"', b'name="inner_step"')
            zout.writestr(item, data)
    ssd = mutated(tmp_path, 'source="project:msd"', 'source="other.fmu"')
    problems = [str(p) for p in api.validate(ssd)]
    assert any("communication steps per macro step would be lost" in p for p in problems), problems
