"""What a user without a checkout starts from: `master examples` copies the project's scenes
(models/) out and each copy runs where it lies; the two-mass oscillator scene follows the
benchmark's exact solution; MASTER_FMU_DIR says where FMUs are built. tests/test_package.py does
the same from an installed wheel."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import master.api as api
from master.cli import main
from master.evidence.oscillator import SET_A, SET_A_X1_10, SET_A_Z0
from master.examples import SCENE_FILE, scene_files

REPO = Path(__file__).resolve().parent.parent
OSCILLATOR = REPO / "models" / "oscillator" / SCENE_FILE


def test_every_scene_is_copied_with_its_files_and_the_command_that_runs_it(tmp_path, capsys):
    dest = tmp_path / "examples"
    assert main(["examples", str(dest)]) == 0
    out = capsys.readouterr().out.splitlines()
    scenes = scene_files()
    assert set(scenes) == {"hydraulic-manipulator", "dc-motor-arm", "oscillator"}  # not models/mechanism
    assert len(out) == 2 * len(scenes)
    for name, files in scenes.items():
        folder = dest / name
        assert sorted(p.name for p in folder.iterdir()) == sorted(f.name for f in files)
        assert all((folder / f.name).read_bytes() == f.read_bytes() for f in files)
        assert any(f.suffix == ".ssv" for f in files) and (folder / "README.md").is_file()
        assert f"{folder}: {', '.join(f.name for f in files)}" in out
        assert f"  master run {folder / SCENE_FILE}" in out
        # the copy finds its parameter files beside it and its FMUs by name (project:...)
        assert api.validate(folder / SCENE_FILE) == []


def test_existing_files_are_kept_unless_forced(tmp_path, capsys):
    dest = tmp_path / "examples"
    assert main(["examples", str(dest)]) == 0
    edited = dest / "oscillator" / "mass1.ssv"
    edited.write_text("mine")
    capsys.readouterr()
    assert main(["examples", str(dest)]) == 1
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith(f"error: {dest}") and "exists" in line and "--force" in line
    assert captured.out == "" and edited.read_text() == "mine"
    assert main(["examples", str(dest), "--force"]) == 0
    assert edited.read_bytes() == (OSCILLATOR.parent / "mass1.ssv").read_bytes()


def test_a_file_in_place_of_the_folder_is_one_line(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("")
    assert main(["examples", str(taken)]) == 1
    assert capsys.readouterr().err == f"error: {taken}: not a folder\n"


def test_oscillator_scene_follows_the_exact_solution():
    """x1 against the matrix exponential: quadratic polynomials handed to the FMUs leave a
    coupling error of 5e-7 m at H = 10 ms (held inputs: 1.4e-3 m); x1(10 s) is the benchmark's."""
    data = api.run(OSCILLATOR, backend="serial").data
    assert data["time"][0] == 0.0 and data["time"][-1] == 10.0 and len(data) == 1001
    exact = SET_A.exact(data["time"], SET_A_Z0)
    assert np.max(np.abs(data["mass1.x"] - exact[:, 0])) < 1e-5
    assert np.max(np.abs(data["mass2.x"] - exact[:, 2])) < 1e-5
    assert abs(data["mass1.x"][-1] - SET_A_X1_10) < 1e-6


def test_fmus_are_built_where_master_fmu_dir_says(tmp_path):
    """Quiet (-q): built without a word; the line that names the folder is tests/test_package.py's."""
    fmus = tmp_path / "fmus"
    env = os.environ | {"MASTER_FMU_DIR": str(fmus)}
    command = [sys.executable, "-m", "master", "run", OSCILLATOR, "--stop-time", "0.02", "-o", "o.csv", "-q"]
    run = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert (fmus / "msd.fmu").is_file() and (tmp_path / "o.csv").is_file()
