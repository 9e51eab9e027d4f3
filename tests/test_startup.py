"""What a short run's start-up relies on: the command line loads nothing it does not need, the
janitor (a shell) removes a killed master's folders and nothing else, one FMU file is extracted
once per run, and fmpy's functions read once per class are fmpy's own."""

import os
import signal
import subprocess
import sys
import tempfile
import time
from fractions import Fraction

import pytest
from fmpy.fmi2 import FMU2Slave

import master.api as api
from master.backends.component import Unpacked, open_fmu
from master.backends.janitor import Janitor
from master.evidence.oscillator import scene
from master.fmu import _signatures_once, read_description
from master.fmubuild import fmu_path

HEAVY = ("numpy", "fmpy", "lxml", "scipy", "master.api")


def test_version_and_help_load_no_machinery():
    code = (
        "import sys\nfrom master.cli import main\n"
        "for argv in (['--version'], ['run', '--help']):\n"
        "    try:\n        main(argv)\n    except SystemExit:\n        pass\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("master ") and "--serial" in r.stdout  # both answered ...
    assert r.stdout.splitlines()[-1] == "[]"  # ... with none of them imported


JANITOR = """
import os, sys, tempfile, time
from master.backends.janitor import Janitor
j = Janitor()
for prefix in ("plain-", "with space -", "with 'quote\\\\ -"):
    d = tempfile.mkdtemp(prefix=prefix)
    open(os.path.join(d, "file"), "w").close()
    j.watch(d)
if sys.argv[1] == "close":
    j.close()
print("ready", flush=True)
time.sleep(60)
"""


@pytest.mark.parametrize("how", ["killed", "closed"])
def test_janitor_removes_a_killed_masters_folders_only(tmp_path, how):
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    arg = "close" if how == "closed" else "keep"
    p = subprocess.Popen([sys.executable, "-c", JANITOR, arg], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert p.stdout.readline() == "ready\n"
        assert len(list(tmp_path.iterdir())) == 3
    finally:
        p.kill()
        p.wait()
    if how == "killed":  # the janitor removes them once the pipe ends
        deadline = time.monotonic() + 10
        while list(tmp_path.iterdir()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(tmp_path.iterdir()) == []
    else:  # told "done": it ended without removing anything
        time.sleep(0.3)
        assert len(list(tmp_path.iterdir())) == 3


def test_janitor_outlives_ctrl_c(tmp_path):
    j = Janitor()
    d = tempfile.mkdtemp(dir=tmp_path)
    j.watch(d)
    time.sleep(0.2)  # the shell has set its traps
    os.kill(j._proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group: not the janitor's
    time.sleep(0.2)
    assert j._proc.poll() is None
    os.close(j._write)  # as when the master dies: the pipe ends without "done"
    assert j._proc.wait(timeout=10) == 0 and not os.path.exists(d)


def test_one_fmu_file_is_extracted_once_per_run(tmp_path):
    sc = scene(split="force", macro_step=Fraction(1, 100), stop_time=Fraction(1, 10), order=2)
    assert len({c.fmu_path for c in sc.components}) == 1 < len(sc.components)
    unpacked = Unpacked(tmp_path)
    fmus = [open_fmu(sc, c, unpacked) for c in sc.components]
    try:
        assert len(list(tmp_path.iterdir())) == 1 and fmus[0].dir == fmus[1].dir
        for f in fmus:
            f.exit_initialization()
            f.do_step(0.0, 0.01)
    finally:
        for f in fmus:
            f.close()
    assert len(list(tmp_path.iterdir())) == 1  # the instances leave the shared files to the run


def test_in_process_run_leaves_no_extracted_fmu(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    sc = scene(split="force", macro_step=Fraction(1, 100), stop_time=Fraction(1, 10), order=2)
    res = api.run(sc, backend="in-process")
    assert res.summary.stop_reason == "finished" and len(res.data) == 11
    assert list(tmp_path.glob("master-run-*")) == []


def test_signatures_read_once_are_fmpys_own(tmp_path):
    path = fmu_path("msd")
    md = read_description(path)
    folder = Unpacked(tmp_path)(path)
    kw = dict(guid=md.guid, modelIdentifier=md.coSimulation.modelIdentifier, unzipDirectory=str(folder))
    slaves = [FMU2Slave(**kw), _signatures_once(FMU2Slave)(**kw), _signatures_once(FMU2Slave)(**kw)]
    try:
        read = [{n: (f.argnames, f.argtypes, f.restype) for n, f in s._functions.items()} for s in slaves]
        own, *once = read
        assert len(own) > 30 and once == [own, own]
        assert all(isinstance(s, FMU2Slave) for s in slaves)
    finally:
        for s in slaves:
            s.freeLibrary()
