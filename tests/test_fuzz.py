"""Property: any mutation of the project's scenario files gives a clean error or a valid run.

Never an unexpected exception (the command line would print a traceback), never a file written
outside the work folder, never a temporary folder left behind. Mutations: attribute values
replaced by hostile text (huge, tiny, negative, non-numeric, long, unicode), attributes,
elements or lines removed or doubled, parameter files damaged. A scene that validates is run
for a few macro steps in worker processes.

Bounded for CI (FUZZ_EXAMPLES, default 100: a few seconds); run longer locally with e.g.
`FUZZ_EXAMPLES=2000 .venv/bin/python -m pytest tests/test_fuzz.py`.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from fractions import Fraction
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import master.api as api
from master.backends.component import SimulationError
from master.fmu import FmuError
from master.scenario import ScenarioError

REPO = Path(__file__).resolve().parent.parent
SCENES = sorted(
    [*(REPO / "tests" / "scenarios").rglob("*.ssd"), *(REPO / "models").glob("*/SystemStructure.ssd")]
)
GOOD = [s for s in SCENES if s.parent.name not in ("bad", "fmi3")]  # valid as they are
CLEAN = (api.UsageError, ScenarioError, FmuError, SimulationError)
EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "100"))
HOSTILE = [
    "",
    " ",
    "0",
    "-1",
    "1e400",
    "-1e309",
    "1e-400",
    "NaN",
    "inf",
    "1/0",
    "0x10",
    "1" * 5000,
    "0." + "0" * 4400 + "1",
    "1e100000000",
    "1000000000",
    "2147483648",
    "true",
    "ab3",
    "..",
    "../../etc/passwd",
    "project:nope",
    "m" * 300,
    "\u00e9\u4e2d",
    "&amp;",
    "0.00001",
    "3",
    "1e-9",
]
ATTRIBUTE = re.compile(r'(\w+(?::\w+)?)="([^"]*)"')


@st.composite
def mutation(draw) -> tuple[Path, str, dict[str, str]]:
    """(scene file, its mutated text, mutated parameter files by name)."""
    scene = draw(st.sampled_from(GOOD)) if draw(st.integers(0, 4)) else draw(st.sampled_from(SCENES))
    text = scene.read_text()
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 3]))):
        kind = draw(
            st.sampled_from(["value", "value", "value", "drop-attribute", "drop-line", "double-line"])
        )
        attrs = list(ATTRIBUTE.finditer(text))
        lines = text.splitlines(keepends=True)
        if kind == "value" and attrs:
            m = draw(st.sampled_from(attrs))
            value = draw(st.one_of(st.sampled_from(HOSTILE), st.text(max_size=20)))
            value = value.replace('"', "").replace("<", "").replace("&", "")
            text = text[: m.start(2)] + value + text[m.end(2) :]
        elif kind == "drop-attribute" and attrs:
            m = draw(st.sampled_from(attrs))
            text = text[: m.start()] + text[m.end() :]
        elif kind in ("drop-line", "double-line") and len(lines) > 2:
            i = draw(st.integers(0, len(lines) - 1))
            lines[i] = "" if kind == "drop-line" else lines[i] * 2
            text = "".join(lines)
    ssv = {}
    for f in scene.parent.glob("*.ssv"):
        if draw(st.integers(0, 9)) == 0:  # now and then, a damaged parameter file
            body = f.read_text()
            cut = draw(st.integers(0, max(len(body) - 1, 0)))
            ssv[f.name] = body[:cut] + draw(st.sampled_from(HOSTILE)) + body[cut:]
    return scene, text, ssv


def snapshot(folder: Path) -> set[str]:
    return {str(p) for p in folder.rglob("*") if "__pycache__" not in p.parts}


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(mutation())
def test_any_mutated_scenario_is_a_clean_error_or_a_valid_run(case):
    scene, text, ssv = case
    before = snapshot(REPO / "tests" / "scenarios") | snapshot(REPO / "models")
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        work = Path(tmp) / "work"
        shutil.copytree(scene.parent, work, ignore=shutil.ignore_patterns("*.py", "*.png", "__pycache__"))
        for name, body in ssv.items():
            (work / name).write_text(body)
        path = work / scene.name
        path.write_text(text)
        temp = Path(tmp) / "temp"
        temp.mkdir()
        old, tempfile.tempdir = tempfile.tempdir, str(temp)
        cwd = os.getcwd()
        os.chdir(work)
        try:
            problems = api.validate(path)  # documented never to raise
            event("valid, run" if not problems else "problems found")
            if not problems:
                sc = api.load_scenario(path)
                stop = sc.start_time + min(5 * sc.macro_step, sc.stop_time - sc.start_time)
                try:
                    api.run(sc, stop_time=Fraction(stop), backend="serial", step_timeout=5)
                except CLEAN:
                    pass
        finally:
            os.chdir(cwd)
            tempfile.tempdir = old
        assert list(temp.iterdir()) == [], "temporary files left behind"
    after = snapshot(REPO / "tests" / "scenarios") | snapshot(REPO / "models")
    assert after == before, f"files written outside the work folder: {sorted(after - before)}"
