"""Backends execute a Plan: `serial` in-process; a parallel one runs the same component code in workers."""
