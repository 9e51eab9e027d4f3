"""Builds the stepping kernel (master/runtime/kernel.c) with the system C compiler, and puts the
sources of the project's FMUs (fmus/) into the package, so that an installed master builds them
on demand as a source checkout does, and the scenes of models/ (master/models, for `master
examples`). The rest of the package is described in pyproject.toml.
The kernel is a plain shared library loaded with ctypes (master/runtime/native.py); it includes
no Python header."""

import importlib.util
import shutil
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
FMU_SOURCES = ("*.c", "*.h", "*.xml")


def _scene_files() -> dict[str, list[Path]]:
    """master/examples.py's scene_files() for models/, loaded by path (the package's own imports
    need its dependencies, which a build may lack)."""
    spec = importlib.util.spec_from_file_location("_examples", ROOT / "master" / "examples.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.scene_files(ROOT / "models")


class BuildWithFmuSources(build_py):
    """build_py that also copies fmus/ (C layer, solvers, models) into master/fmus of the build,
    and each scene of models/ into master/models."""

    def run(self):
        super().run()
        src = ROOT / "fmus"
        dst = Path(self.build_lib) / "master" / "fmus"
        for pattern in FMU_SOURCES:
            for path in src.rglob(pattern):
                target = dst / path.relative_to(src)
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target)
        for name, files in _scene_files().items():
            target = Path(self.build_lib) / "master" / "models" / name
            target.mkdir(parents=True, exist_ok=True)
            for path in files:
                shutil.copy2(path, target / path.name)


setup(
    cmdclass={"build_py": BuildWithFmuSources},
    ext_modules=[
        Extension(
            "master.runtime._kernel",
            # the shared fixed-step solvers and LU of the project's FMUs (master/runtime/native.py)
            sources=[
                "master/runtime/kernel.c",
                "fmus/solvers/solvers.c",
                "fmus/solvers/lu.c",
                "fmus/solvers/events.c",
            ],
            depends=[
                "master/runtime/kernel.h",
                "master/runtime/scheduled.c",
                "fmus/solvers/solvers.h",
                "fmus/fmi/model.h",
            ],
            include_dirs=["fmus/solvers", "fmus/fmi"],
            extra_compile_args=["-std=c99", "-ffp-contract=off", "-Wall", "-Wextra"],
            libraries=["m"],
        )
    ],
)
