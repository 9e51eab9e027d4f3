"""Builds the stepping kernel (master/runtime/kernel.c) with the system C compiler; the rest of the
package is described in pyproject.toml. The kernel is a plain shared library loaded with ctypes
(master/runtime/native.py); it includes no Python header."""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "master.runtime._kernel",
            sources=["master/runtime/kernel.c"],
            depends=["master/runtime/kernel.h"],
            extra_compile_args=["-std=c99", "-ffp-contract=off", "-Wall", "-Wextra"],
            libraries=["m"],
        )
    ]
)
