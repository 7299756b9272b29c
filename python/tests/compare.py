"""Value comparison of decoded messages, as the vectors' README asks:
doubles within 1e-9 relative, everything else exactly."""

import math


def same(a, b):
    """True when two JSON-shaped values (dicts, lists, numbers, str) are equal,
    numbers within 1e-9 relative; 64-bit integers written as strings compare as numbers."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    a, b = _number(a), _number(b)
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if isinstance(a, float) or isinstance(b, float):
            if math.isnan(a) or math.isnan(b):
                return math.isnan(a) and math.isnan(b)
            return a == b or abs(a - b) <= 1e-9 * max(abs(a), abs(b))
        return a == b
    return a == b


def _number(v):
    if isinstance(v, str):
        try:
            return int(v)
        except ValueError:
            if v in ("NaN", "Infinity", "-Infinity"):
                return float(v.replace("Infinity", "inf"))
    return v
