"""Builds the stepping kernel (master/runtime/kernel.c) with the system C compiler, and puts the
sources of the project's FMUs (fmus/) into the package, so that an installed master builds them
on demand as a source checkout does. The rest of the package is described in pyproject.toml.
The kernel is a plain shared library loaded with ctypes (master/runtime/native.py); it includes
no Python header."""

import shutil
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_py import build_py

FMU_SOURCES = ("*.c", "*.h", "*.xml")


class BuildWithFmuSources(build_py):
    """build_py that also copies fmus/ (C layer, solvers, models) into master/fmus of the build."""

    def run(self):
        super().run()
        src = Path(__file__).resolve().parent / "fmus"
        dst = Path(self.build_lib) / "master" / "fmus"
        for pattern in FMU_SOURCES:
            for path in src.rglob(pattern):
                target = dst / path.relative_to(src)
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target)


setup(
    cmdclass={"build_py": BuildWithFmuSources},
    ext_modules=[
        Extension(
            "master.runtime._kernel",
            sources=["master/runtime/kernel.c"],
            depends=["master/runtime/kernel.h"],
            extra_compile_args=["-std=c99", "-ffp-contract=off", "-Wall", "-Wextra"],
            libraries=["m"],
        )
    ],
)
