"""Backends execute a Plan: `serial` in-process; a parallel backend runs the same component code in workers."""
