"""The stability suite of `sphere verify` (verification group E), one test per
case: each must refuse, run stably or report a numerical failure as it promises, and the dt
search must show that every dt the builder accepts is stable.

The builder's contact limit is that of velocity Verlet with the dashpots at the predicted
velocity v_n + dt a_n, 2 (sqrt(1 + 4 zeta^2) - 2 zeta)/omega (det(M + I) = 4 - h^2 - 8 zeta h for
the amplification matrix M of (x, v, a), h = omega dt), for the normal mode and for the
rolling-coupled tangential mode with its damping ratio sqrt(3.5) zeta (physics/contact.py); the
two damped "stability-limit" cases check that every dt it accepts is stable.
"""

from __future__ import annotations

import pytest

from sphere_cli.verify.stability import STABILITY, run_stability_case, scheme_limit

KNOWN_DEFECTS: dict[str, str] = {}


PARAMS = [
    pytest.param(
        name,
        marks=[pytest.mark.xfail(strict=True, reason=KNOWN_DEFECTS[name])] if name in KNOWN_DEFECTS else [],
        id=name,
    )
    for name in STABILITY
]


@pytest.mark.parametrize("name", PARAMS)
def test_stability_case(name):
    record = run_stability_case(STABILITY[name], quick=True)
    failed = [f"{c['check']}: {c['detail']}" for c in record["checks"] if not c["passed"]]
    assert record["passed"], "; ".join(failed)
    assert record["action"] == STABILITY[name].expected


def test_scheme_limit_closed_form():
    """2 (sqrt(1 + 4 zeta^2) - 2 zeta)/omega: 2/omega undamped, below the central-difference
    2 (sqrt(1 + zeta^2) - zeta)/omega when damped, and an eigenvalue of the amplification
    matrix of (x, v, a) sits on -1 there."""
    import numpy as np

    assert scheme_limit(1.0, 0.0) == 2.0
    for zeta in (0.05, 0.25, 0.7, 1.5):
        h = scheme_limit(1.0, zeta)
        assert h < 2.0 * (np.sqrt(1.0 + zeta**2) - zeta)
        m = np.array(
            [
                [1.0, h, h * h / 2],
                [-h / 2, 1 - h * h / 2 - zeta * h, h / 2 - h**3 / 4 - zeta * h * h],
                [-1.0, -h - 2 * zeta, -h * h / 2 - 2 * zeta * h],
            ]
        )
        assert np.min(np.abs(np.linalg.eigvals(m) + 1.0)) < 1e-6
