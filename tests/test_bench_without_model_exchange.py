"""bench and tune on a scene whose FMUs have no Model Exchange interface (a pythonfmu3 FMU): the
reference is a converged co-simulation, or a best-effort one named as such; never a traceback,
and the scene's warnings said once however many runs the bench makes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from master.api import load_scenario
from master.evidence.reference import STALLED, NotConverged, converged_cosimulation, has_model_exchange, solve

SOURCE = Path(__file__).parent / "scenarios" / "fmi3"
BIN = Path(sys.executable).parent
WARNING = "needsExecutionTool"
# the body starts displaced, so that the loop moves; a counter recorded (`lag.steps`: steps taken)
# changes with every halving of the macro step, so the co-simulation never converges
BODY = '<ssc:Real unit="m"/></ssd:Connector>\n        </ssd:Connectors>'
DISPLACED = (
    BODY
    + """
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="start"><ssv:Parameters>
            <ssv:Parameter name="x0"><ssv:Real value="1"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>"""
)
COUNTED = """<mm:Component name="lag" stepRatio="2"/>
          <mm:Record><mm:Variable component="lag" name="y"/><mm:Variable component="lag" name="steps"/>
          </mm:Record>"""


@pytest.fixture(scope="module")
def scenes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """lag_and_body.ssd (Lag3.fmu: FMI 3.0, Co-Simulation only) beside a freshly built Lag3.fmu,
    as is with the body displaced ("moving") and recording the lag's step counter ("counting")."""
    folder = tmp_path_factory.mktemp("no-me")
    subprocess.run([sys.executable, "-m", "pythonfmu3", "build", "-f", str(SOURCE / "Lag3.py"), "-d",
                    str(folder)], check=True, capture_output=True, timeout=120)  # fmt: skip
    text = (SOURCE / "lag_and_body.ssd").read_text().replace(BODY, DISPLACED)
    (folder / "moving.ssd").write_text(text.replace("0.01", "0.05"))
    (folder / "counting.ssd").write_text(text.replace('<mm:Component name="lag" stepRatio="2"/>', COUNTED))
    return {name: folder / f"{name}.ssd" for name in ("moving", "counting")}


def _master(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "master"), *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_a_counter_stalls_the_convergence_early_and_leaves_a_best_effort(scenes):
    sc = load_scenario(scenes["counting"])
    assert not has_model_exchange(sc)
    with pytest.raises(NotConverged) as info:
        converged_cosimulation(sc)
    conv = info.value.convergence
    assert len(conv.changes) == STALLED + 1  # given up after STALLED halvings without progress
    assert conv.variable == "lag.steps" and conv.last_change >= 0.5  # the count doubles each time
    assert set(info.value.trajectory.values) == {"lag.y", "lag.steps"}
    ref = solve(sc, cache_dir=None)
    assert not ref.converged and "best-effort reference" in ref.what and "lag.steps" in ref.what


def test_without_a_record_list_the_reference_compares_the_floating_point_outputs(scenes):
    """An unrecorded counter is no signal to converge on: the scene's float outputs converge."""
    ref = solve(load_scenario(scenes["moving"]), cache_dir=None, cosim_tol=1e-2)
    assert ref.converged and "lag.steps" not in ref.trajectory.values
    assert {"lag.y", "body.x"} <= set(ref.trajectory.values)


def test_bench_names_a_best_effort_reference_and_says_a_warning_once(scenes, tmp_path):
    proc = _master("bench", str(scenes["counting"]), "--quick", "--repeats", "2", "--out", "b", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    said = [line for line in proc.stdout.splitlines() if "reference" in line]
    assert len(said) == 1 and said[0].startswith("errors against a best-effort reference:")
    # 4 configurations x 2 repeats and the reference's runs: the FMU's warning once
    assert (proc.stdout + proc.stderr).count(WARNING) == 1
    assert (tmp_path / "b" / "counting-quick.csv").exists()


def test_tune_refuses_a_tolerance_a_best_effort_reference_cannot_check_in_one_line(scenes, tmp_path):
    proc = _master("tune", str(scenes["counting"]), "--tolerance", "1e-3", cwd=tmp_path)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "cannot be checked against a best-effort reference" in errors[0]
    assert proc.stderr.count(WARNING) == 1
    assert not scenes["counting"].with_suffix(".tuned.ssd").exists()
