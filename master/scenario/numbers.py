"""Numbers in scenario files, parsed with bounded cost and range."""

from __future__ import annotations

import re
from fractions import Fraction

_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
MAX_TIME_CHARS = 40  # a time written with more characters than this is refused, not parsed
MAX_EXPONENT = 30
MAX_TIME = 10**12  # s (some 30,000 years): beyond it no run is meant


def parse_time(text: str) -> Fraction:
    """An exact time (s) from a decimal string ("0.0002" -> 1/5000); never through a float.

    Bounded cost and range: at most MAX_TIME_CHARS characters, exponents within +-MAX_EXPONENT,
    |time| <= MAX_TIME. Raises ValueError saying what is wrong otherwise."""
    t = text.strip()
    if len(t) > MAX_TIME_CHARS:
        raise ValueError(f'"{t[:12]}..." has {len(t)} characters (at most {MAX_TIME_CHARS})')
    m = _DECIMAL.fullmatch(t)
    if m is None:
        raise ValueError(f'"{t}" is not a decimal number (such as 0.001 or 1e-3)')
    if m.group(2) and abs(int(m.group(2)[1:])) > MAX_EXPONENT:
        raise ValueError(f'"{t}": the exponent is beyond +-{MAX_EXPONENT}')
    value = Fraction(t)
    if abs(value) > MAX_TIME:
        raise ValueError(f'"{t}" is beyond {MAX_TIME:.0e} s')
    return value
