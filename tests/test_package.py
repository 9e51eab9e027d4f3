"""A real package install: a wheel built from the checkout, installed into a fresh virtual
environment, runs a scene from outside the checkout (the FMU sources ship in the package and are
built into the user's cache; the kernel is compiled into the wheel)."""

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

from fmpy.util import read_csv

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
        ]
    )

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {
        "XDG_CACHE_HOME": str(tmp_path / "cache")
    }
    where = run(
        [fresh / "bin" / "python", "-c", "import master; print(master.__file__)"], cwd=tmp_path, env=env
    )
    assert where.stdout.strip().startswith(str(site))
    out = tmp_path / "out.csv"
    scene = REPO / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"
    run([fresh / "bin" / "master", "run", scene, "--stop-time", "1", "-o", out, "-q"], cwd=tmp_path, env=env)
    data = read_csv(str(out))
    assert len(data) == 11 and data["time"][-1] == 1.0 and abs(data["mass1.x"][0] - 1.0) < 1e-12
    assert (tmp_path / "cache" / "multirate-master" / "fmus" / "msd.fmu").is_file()
    # the installed kernel is used as pip built it: no compiler needed once the FMU is cached
    bare = env | {"PATH": str(fresh / "bin")}
    run([fresh / "bin" / "master", "run", scene, "--stop-time", "1", "-o", out, "-q"], cwd=tmp_path, env=bare)
