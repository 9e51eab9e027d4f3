"""Backends execute a Plan: `serial` in-process; a parallel one runs the same component code in workers."""

BACKENDS = ("serial", "parallel", "auto", "in-process")  # here: the command line lists them before any import
