"""io/json_text.py: strict JSON for other programs (no NaN or Infinity tokens)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from sphere_cli.io.json_text import json_text


def test_non_finite_values_are_null_and_numpy_values_plain():
    data = {
        "nan": float("nan"),
        "inf": -math.inf,
        "scalar": np.float64(np.nan),
        "count": np.int64(3),
        "array": np.array([[1.5, np.inf], [np.nan, 2.0]]),
        "nested": ({"x": np.float32(0.25)}, [Path("/tmp/run")]),
        "text": "NaN",
    }

    def refuse(token):
        raise ValueError(token)

    assert json.loads(json_text(data), parse_constant=refuse) == {
        "nan": None,
        "inf": None,
        "scalar": None,
        "count": 3,
        "array": [[1.5, None], [None, 2.0]],
        "nested": [{"x": 0.25}, ["/tmp/run"]],
        "text": "NaN",
    }
