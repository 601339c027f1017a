"""JSON that other programs read (inspect --json, sweep-summary --json, status.json, verify.json,
the benchmarks' files): strict JSON (RFC 8259), which has no NaN or infinity. Python's json
module writes them as the bare tokens NaN and Infinity, which JavaScript's JSON.parse, Go's
encoding/json, serde_json and other strict parsers refuse, so a whole report became unreadable
for one observable without a value (the coordination of a sample without interior). They are
written as null, "no value"; NumPy scalars and arrays as numbers and lists, paths as strings."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def plain(value):
    """`value` with every NaN and infinity replaced by None, NumPy values by Python ones and
    paths by strings, inside dicts, lists and tuples."""
    if isinstance(value, dict):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [plain(item) for item in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def json_text(data, indent: int | None = 2) -> str:
    return json.dumps(plain(data), indent=indent, allow_nan=False)
