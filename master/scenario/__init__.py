"""Scenario files: SSP 1.0 or 2.0 (.ssd / .ssp with .ssv parameter sets) plus the master's
optional settings annotation, read into a validated, immutable `Scenario`.
Format: docs/scenario-format.md."""

from .check import check
from .model import Component, Connection, Scenario, Stimulus, Value
from .problems import Problem, ScenarioError
from .reader import load, parse_time, read, validate

__all__ = [
    "Component",
    "Connection",
    "Problem",
    "Scenario",
    "ScenarioError",
    "Stimulus",
    "Value",
    "check",
    "load",
    "parse_time",
    "read",
    "validate",
]
