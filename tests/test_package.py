"""A real package install: a wheel built from the checkout, installed into a fresh virtual
environment, copies its example scenes out (`master examples`) and runs one from another folder
(the FMU sources ship in the package and are built into the user's cache, which the run names;
the kernel is compiled into the wheel)."""

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

from fmpy.util import read_csv

from master.examples import scene_files

REPO = Path(__file__).resolve().parent.parent


def run(args, **kw) -> subprocess.CompletedProcess:
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=300, **kw)
    assert r.returncode == 0, r.stderr
    return r


def test_wheel_installs_into_a_fresh_environment_and_runs_a_scene(tmp_path):
    # no network: the running environment's setuptools and wheel build it
    run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-build-isolation",
            "--no-deps",
            "-q",
            "-w",
            tmp_path,
            REPO,
        ]
    )
    (wheel,) = tmp_path.glob("master-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert any(n.startswith("master/runtime/_kernel") and n.endswith(".so") for n in names)
    assert "master/fmus/msd/model.c" in names and "master/fmus/fmi/fmi2.c" in names
    assert "master/schemas/multirate-settings.xsd" in names
    scenes = scene_files()
    assert {"hydraulic-manipulator", "dc-motor-arm", "oscillator"} <= set(scenes)
    assert {f"master/models/{scene}/{f.name}" for scene, files in scenes.items() for f in files} <= set(names)

    fresh = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", fresh])
    site = Path(
        run(
            [fresh / "bin" / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]
        ).stdout.strip()
    )
    # the dependencies (numpy, fmpy, ...) from the running environment, as a plain path: its .pth
    # files, among them the editable install of this checkout, are not read from there
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    # without PYTHONPATH: a checkout on it (with the master.egg-info the wheel build leaves there)
    # would count as master installed already, and pip would skip the wheel
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {
        "XDG_CACHE_HOME": str(tmp_path / "cache")
    }
    run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            fresh / "bin" / "python",
            "install",
            "--no-deps",
            "--no-index",
            "-q",
            wheel,
        ],
        env=env,
    )
    where = run(
        [fresh / "bin" / "python", "-c", "import master; print(master.__file__)"], cwd=tmp_path, env=env
    )
    assert where.stdout.strip().startswith(str(site))
    copied = run([fresh / "bin" / "master", "examples", "ex"], cwd=tmp_path, env=env).stdout
    for scene in scenes:
        assert f"master run {Path('ex', scene, 'SystemStructure.ssd')}\n" in copied
    # from another folder: the scene finds its parameter files beside it and builds its FMUs
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "out.csv"
    scene = Path("..", "ex", "oscillator", "SystemStructure.ssd")
    cache = tmp_path / "cache" / "multirate-master" / "fmus"
    ran = run(
        [fresh / "bin" / "master", "run", scene, "--stop-time", "0.1", "-o", out], cwd=elsewhere, env=env
    )
    assert f"building FMU msd (FMI 2.0) from its C sources into {cache} ..." in ran.stderr.splitlines()
    data = read_csv(str(out))
    # mass1.ssv's start position, one row per macro step of 0.01 s
    assert len(data) == 11 and data["time"][-1] == 0.1 and abs(data["mass1.x"][0] - 1.0) < 1e-12
    assert (cache / "msd.fmu").is_file()
    # the installed kernel is used as pip built it: no compiler needed once the FMU is cached
    bare = env | {"PATH": str(fresh / "bin")}
    again = run(
        [fresh / "bin" / "master", "run", scene, "--stop-time", "0.1", "-o", out], cwd=elsewhere, env=bare
    )
    assert "building FMU" not in again.stderr
