"""Command-line smoke tests through real subprocesses (`python -m master ...`)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy.util import read_csv
from helpers import started
from PIL import Image

from master.cli import scene_stem
from master.fmubuild import fmu_path
from master.recorder import result_figure

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="decay"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="decay">
    <ssd:Elements>
      <ssd:Component name="d" source="project:dahlquist">
        <ssd:Connectors>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}">
    <ssd:Annotations>
      <ssc:Annotation type="org.multirate-master.settings">
        <mm:Settings macroStep="{step}"/>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def master(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "master", *args], capture_output=True, text=True, cwd=cwd, timeout=120
    )


@pytest.fixture
def decay(tmp_path) -> Path:
    fmu_path("dahlquist")  # build once, before the subprocesses need it
    p = tmp_path / "decay.ssd"
    p.write_text(SSD.format(stop="1", step="0.01"))
    return p


@pytest.mark.parametrize("cmd", [[], ["run"], ["validate"], ["info"], ["plot"]])
def test_help(cmd):
    r = master(*cmd, "--help")
    assert r.returncode == 0 and "usage: master" in r.stdout


def test_run_writes_csv_and_plot(decay, tmp_path):
    out, png = tmp_path / "out.csv", tmp_path / "out.png"
    r = master(
        "run", str(decay), "-o", str(out), "--set", "d.lambda=-2", "--stop-time", "0.5", "--plot", str(png)
    )
    assert r.returncode == 0, r.stderr
    assert "real-time factor" in r.stdout and "overhead" in r.stdout
    data = read_csv(str(out))
    assert data.dtype.names == ("time", "d.y")
    assert data["time"][-1] == 0.5 and len(data) == 51
    assert data["d.y"][-1] == pytest.approx(np.exp(-1.0), rel=1e-6)  # RK4 at h = 0.01
    assert png.stat().st_size > 1000
    r = master(
        "run",
        str(decay),
        "-o",
        str(tmp_path / "par.csv"),
        "--set",
        "d.lambda=-2",
        "--stop-time",
        "0.5",
        "--parallel",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "par.csv").read_text() == out.read_text()  # same numbers from both backends
    r = master("plot", str(out), "-o", str(tmp_path / "again.png"))
    assert r.returncode == 0 and (tmp_path / "again.png").exists()
    # titled by the scene's name (the metadata's), else by the file's; an axis without a unit unlabelled
    assert png_title(png) == png_title(tmp_path / "again.png") == "decay"
    (tmp_path / "out.json").unlink()
    assert master("plot", str(out)).returncode == 0 and png_title(tmp_path / "out.png") == "out.csv"
    fig = result_figure(read_csv(str(out)), units={"d.y": None})
    assert [ax.get_ylabel() for ax in fig.axes] == [""]


def png_title(png: Path) -> str:
    """The "Title" a PNG file carries."""
    with Image.open(png) as image:
        return image.text["Title"]


def test_validate_info(decay):
    assert master("validate", str(decay)).returncode == 0
    r = master("info", str(decay))
    assert r.returncode == 0 and "d: k = 1, h = 1/100 s" in r.stdout
    r = master("info", str(fmu_path("dahlquist")))
    assert r.returncode == 0 and "canInterpolateInputs=True" in r.stdout and "lambda" in r.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["run", "missing.ssd"], "missing.ssd: no such scenario file"),
        (["run", "{decay}", "--backend", "threads"], "invalid choice"),
        (["run", "{decay}", "--set", "d.nope=1"], "nope"),
        (["run", "{decay}", "--stop-time", "0.015"], "not a whole number of macro steps"),
        (["run", "{decay}", "--record", "x.y"], "--record x.y"),
        (
            ["run", "{decay}", "--record", "d.nope"],
            "decay.ssd: record d.nope: unknown variable: the FMU of d",
        ),
        (["run", "{decay}", "--output-interval", "0.015"], "decay.ssd: record interval: interval 0.015 s"),
        (["plot", "missing.csv"], "missing.csv"),
    ],
)
def test_user_errors_exit_non_zero_without_traceback(decay, args, message):
    r = master(*[a.format(decay=decay) for a in args])
    assert r.returncode != 0
    assert message in r.stderr
    assert "Traceback" not in r.stderr
    if r.returncode == 1:  # the master's own refusal (2: argparse's usage), in one line
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_invalid_scenario_is_reported(tmp_path):
    bad = tmp_path / "bad.ssd"
    bad.write_text(SSD.format(stop="1", step="0.01").replace("project:dahlquist", "nothere.fmu"))
    r = master("validate", str(bad))
    assert r.returncode == 1 and "bad.ssd" in r.stdout
    r = master("run", str(bad))
    assert r.returncode == 1 and "bad.ssd" in r.stderr and "Traceback" not in r.stderr


PEAK = "import resource as r, sys; from master.cli import main; rc = main(sys.argv[1:]); " + (
    "print(max(r.getrusage(w).ru_maxrss for w in (r.RUSAGE_SELF, r.RUSAGE_CHILDREN))); sys.exit(rc)"
)  # the master or its worker, whichever peaked higher


def peak_kib(ssd: Path, out: Path) -> int:
    r = subprocess.run(
        [sys.executable, "-c", PEAK, "run", str(ssd), "-o", str(out), "-q"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    return int(r.stdout.split()[-1])


def test_results_stream_to_disk_memory_stays_flat(tmp_path):
    """10^5 recorded steps peak within 50 MB of 10^3 (benchmarks/overhead.py --memory checks 10^6)."""
    fmu_path("dahlquist")
    small, big = tmp_path / "small.ssd", tmp_path / "big.ssd"
    small.write_text(SSD.format(stop="1", step="0.001"))
    big.write_text(SSD.format(stop="1", step="0.00001"))
    p_small = peak_kib(small, tmp_path / "small.csv")
    p_big = peak_kib(big, tmp_path / "big.csv")
    assert len((tmp_path / "big.csv").read_text().splitlines()) == 100_002
    assert p_big - p_small < 50 * 1024, (p_small, p_big)


# -- one clear line, never a traceback (issue: a clean first hour) -------------------------------


def test_version():
    r = master("--version")
    assert r.returncode == 0 and r.stdout.startswith("master ")


@pytest.mark.parametrize(
    "case, args, code, said",
    [
        ("fmu-as-scenario", ["run", "{fmu}"], 1, "an FMU, not a scenario"),
        ("plot-non-csv", ["plot", "{readme}"], 1, "not a results CSV file"),
        ("png-as-output", ["run", "{ssd}", "-o", "{tmp}/x.png"], 1, "name a .csv file"),
        ("output-is-directory", ["run", "{ssd}", "-o", "{tmp}/dir.csv"], 1, "cannot write the results there"),
        (
            "output-under-a-file",
            ["run", "{ssd}", "-o", "{readme}/x.csv"],
            1,
            "cannot write the results there",
        ),
        (
            "plot-under-a-file",
            ["run", "{ssd}", "-o", "{tmp}/ok.csv", "--plot", "{readme}/x.png"],
            1,
            "--plot",
        ),
        ("zero-real-time", ["run", "{ssd}", "--real-time", "0"], 2, "expected a positive number"),
        ("bad-cpus", ["run", "{ssd}", "--cpus", "x"], 2, "expected processor numbers"),
        ("foreign-cpus", ["run", "{ssd}", "--cpus", "4096"], 1, "not processors this process may use"),
        ("cpus-in-process", ["run", "{ssd}", "--cpus", "0", "--in-process"], 1, "--in-process runs without"),
    ],
)
def test_bad_input_gives_one_line(case, args, code, said, decay, tmp_path):
    (tmp_path / "dir.csv").mkdir()
    readme = Path(__file__).resolve().parent.parent / "README.md"
    subs = {"fmu": str(fmu_path("dahlquist")), "readme": str(readme), "ssd": str(decay), "tmp": str(tmp_path)}
    r = master(*(a.format(**subs) for a in args), cwd=tmp_path)
    assert r.returncode == code, r.stderr
    assert said in r.stderr and "Traceback" not in r.stderr
    assert sum("error:" in line for line in r.stderr.splitlines()) == 1, r.stderr
    assert not list(tmp_path.glob("master_results_*")) and not list(tmp_path.glob("master-run-*"))


def test_run_without_output_writes_under_results_and_says_where(decay, tmp_path):
    r = master("run", str(decay), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (csv,) = (tmp_path / "results").glob("decay-*.csv")
    assert f"rows written to {Path('results') / csv.name}" in r.stdout
    assert len(read_csv(str(csv))) == 101


def test_the_default_results_of_a_generic_system_structure_are_named_after_its_folder(decay, tmp_path):
    """models/<scene>/SystemStructure.ssd writes results/<scene>-DATE-TIME.csv, not SystemStructure-..."""
    scene = tmp_path / "decay-scene"
    scene.mkdir()
    (scene / "SystemStructure.ssd").write_text(decay.read_text())
    r = master("run", str(scene / "SystemStructure.ssd"), "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (csv,) = (tmp_path / "results").glob("*.csv")
    assert csv.name.startswith("decay-scene-") and len(read_csv(str(csv))) == 101
    assert scene_stem(str(scene / "SystemStructure.ssd")) == "decay-scene" == scene_stem("decay-scene.ssp")
    assert scene_stem("SystemStructure.ssd") == Path.cwd().name


def test_closed_pipe_ends_quietly():
    """`master info X | head -1`: the reader goes away, master ends without a traceback."""
    cmd = [sys.executable, "-m", "master", "info", fmu_path("dahlquist")]
    with started(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        proc.stdout.close()  # nobody reads: the first write fails
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=60) == 0 and "Traceback" not in err and "BrokenPipe" not in err


def test_subcommand_help_names_itself():
    assert master("build-fmus", "--help").stdout.startswith("usage: master build-fmus")
    text = master("bench", "--help").stdout
    assert text.startswith("usage: master bench") and "plot wall time against error." in text


def test_readme_usage_block_lists_every_run_option():
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    usage = readme[readme.index("master run SCENARIO") : readme.index("master validate")]
    # each option of `master run --help` (either spelling of one with two) appears in the block
    lines = [ln.strip() for ln in master("run", "--help").stdout.splitlines() if ln.strip().startswith("-")]
    spellings = [[w.strip(",") for w in ln.split() if w.startswith("-")] for ln in lines]
    missing = sorted(s[0] for s in spellings if s[0] != "-h" and not any(w in usage for w in s))
    assert not missing, f"README usage block lacks {missing}"


def test_results_metadata_beside_the_csv(decay, tmp_path):
    """out.json beside out.csv: each column's unit and the run summary, with the real-time
    lateness histogram of a paced run."""
    out = tmp_path / "out.csv"
    r = master("run", str(decay), "-o", str(out), "--real-time", "10", "-q")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "out.json").read_text())
    assert meta["units"] == {"d.y": None}  # the Dahlquist FMU's y has no unit
    assert meta["types"] == {"time": "float64", "d.y": "float64"}  # as the results hold them
    s = meta["summary"]
    assert s["stop_reason"] == "finished" and s["macro_steps"] == 100
    assert sum(n for _, n in s["lateness_histogram"]) >= 100 and s["lateness"]["p50"] >= 0


# -- an optional extra missing: one line naming the pip command, before any work ----------------

BLOCKING = """import sys
BLOCKED = set(sys.argv.pop(1).split(","))
class Absent:  # as if these packages were not installed
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Absent())
from master.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize(
    "blocked, args, extra",
    [
        ("matplotlib", ["run", "{ssd}", "--plot", "x.png"], "plot"),
        ("matplotlib", ["plot", "{csv}"], "plot"),
        ("pyarrow", ["sweep", "{ssd}", "--vary", "d.lambda=-1:-2:2"], "sweep"),
        ("distributed", ["sweep", "{ssd}", "--vary", "d.lambda=-1:-2:2"], "sweep"),
        ("zarr", ["sweep", "{ssd}", "--vary", "d.lambda=-1:-2:2", "--series"], "sweep"),
        ("matplotlib", ["sweep", "{ssd}", "--vary", "d.lambda=-1:-2:2", "--plot", "s.png"], "plot"),
        ("matplotlib", ["bench", "{ssd}", "--quick"], "plot"),
        ("distributed", ["bench", "{ssd}", "--quick"], "sweep"),
    ],
)
def test_a_missing_extra_is_one_line_naming_pip_before_any_work(blocked, args, extra, decay, tmp_path):
    (tmp_path / "run").mkdir()
    csv = tmp_path / "x.csv"
    csv.write_text("time,d.y\n0,1\n")
    subs = {"ssd": str(decay), "csv": str(csv)}
    r = subprocess.run(
        [sys.executable, "-c", BLOCKING, blocked, *(a.format(**subs) for a in args)],
        capture_output=True,
        text=True,
        cwd=tmp_path / "run",
        timeout=120,
    )
    assert r.returncode == 1, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert f"pip install 'master[{extra}]'" in line and blocked in line, line
    assert list((tmp_path / "run").iterdir()) == []  # no results folder, no plot, no CSV
    assert not list(tmp_path.glob("*.png"))


def test_the_python_api_refuses_a_plot_without_matplotlib_before_the_run(decay, tmp_path):
    prelude = BLOCKING.split("from master.cli")[0].replace("sys.argv.pop(1)", "'matplotlib'")
    code = prelude + (
        "import master\n"
        "from master.extras import MissingExtra\n"
        "try:\n"
        f"    master.run({str(decay)!r}, output='out.csv', plot='out.png')\n"
        "except MissingExtra as e:\n"
        "    print(e)\n"
    )
    (tmp_path / "run").mkdir()
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path / "run",
                       timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "pip install 'master[plot]'" in r.stdout and list((tmp_path / "run").iterdir()) == []


def test_the_extras_table_names_only_modules_its_extra_installs():
    """master.extras.NEEDS against pyproject.toml: each module is one its extra's packages provide."""
    from master.extras import NEEDS

    tomllib = pytest.importorskip("tomllib")  # Python 3.11 on

    project = tomllib.loads((Path(__file__).resolve().parent.parent / "pyproject.toml").read_text())
    declared = project["project"]["optional-dependencies"]
    provides = {"dask[distributed]": {"distributed", "dask"}}
    for command, _, extra, modules in NEEDS:
        packages = [d.split(">")[0].split("=")[0] for d in declared[extra]]
        names = set().union(*(provides.get(p, {p}) for p in packages))
        assert set(modules) <= names, (command, extra, modules, packages)


# -- messages that say what is wrong ------------------------------------------------------------


def test_master_alone_lists_the_commands():
    r = master()
    assert r.returncode == 2 and r.stderr.startswith("usage: master")
    for command in ("run", "validate", "info", "plot", "sweep", "tune", "build-fmus", "bench"):
        assert f"\n    {command}" in r.stderr, command


def test_an_unknown_option_shows_the_commands_usage(decay):
    r = master("run", str(decay), "--stoptime", "1")
    assert r.returncode == 2 and r.stderr.startswith("usage: master run ")
    assert "master run: error: unrecognized arguments: --stoptime 1 (did you mean --stop-time?)" in r.stderr


def test_an_fmu_or_a_results_file_is_not_a_scenario(tmp_path):
    fmu = str(fmu_path("dahlquist"))
    r = master("validate", fmu)
    assert r.returncode == 1 and "an FMU, not a scenario" in r.stdout and "XML" not in r.stdout
    assert f"`master info {fmu}` describes it" in r.stdout
    csv = tmp_path / "x.csv"
    csv.write_text("time,d.y\n0,1\n")
    for command in ("run", "validate", "info"):
        r = master(command, str(csv))
        said = r.stderr + r.stdout
        assert r.returncode == 1 and "x.csv: file: not a scenario: expected an .ssd or .ssp file" in said
        assert "XML" not in said and "Traceback" not in said


def test_a_folder_runs_the_scenario_it_holds(decay, tmp_path):
    scene = tmp_path / "scene"
    scene.mkdir()
    decay.rename(scene / "decay.ssd")
    r = master("run", str(scene), "-o", str(tmp_path / "out.csv"), "-q")
    assert r.returncode == 0, r.stderr
    assert len(read_csv(str(tmp_path / "out.csv"))) == 101
    (scene / "other.ssp").write_bytes(b"")
    r = master("validate", str(scene))
    assert r.returncode == 1
    assert "scene: folder: holds several scenarios (decay.ssd, other.ssp): name one" in r.stdout
    (scene / "SystemStructure.ssd").write_text((scene / "decay.ssd").read_text())
    assert master("validate", str(scene)).stdout.strip() == f"{scene}: ok"  # the SSP name wins
    empty = tmp_path / "empty"
    empty.mkdir()
    r = master("run", str(empty))
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert (
        "empty: folder: holds no scenario: expected SystemStructure.ssd or one .ssd or .ssp file" in r.stderr
    )


def test_info_names_fmi3_types():
    r = master("info", str(fmu_path("alltypes", fmi=3)))
    assert r.returncode == 0, r.stderr
    types = {line.split()[0]: line.split()[3] for line in r.stdout.splitlines()[3:]}
    assert types["y_float32"] == "Float32" and types["y_int64"] == "Int64" and types["y_uint8"] == "UInt8"
    assert types["y_float64"] == "Float64" and types["y_boolean"] == "Boolean"
