"""Damping calibration: the restitution a user asks for is the restitution the contact gives.

Both normal laws are clamped, F_n = max(0, elastic + damping) (never attractive), so the
contact ends when the force reaches zero, which happens before the overlap returns to zero.

Linear spring-dashpot (Schwager & Poeschel 2007, Granular Matter 9:465; verification group A1):
    m* delta'' = -(k delta + c delta'),  omega0 = sqrt(k/m*),  zeta = c/(2 sqrt(k m*)).
For zeta < 1, delta = (v/omega) exp(-zeta omega0 t) sin(omega t), omega = omega0 sqrt(1-zeta^2).
The force vanishes at omega t_end = atan2(2 zeta s, 2 zeta^2 - 1), s = sqrt(1-zeta^2), i.e.
tan(omega t_end) = -2 zeta s/(1 - 2 zeta^2) on the branch in (0, pi). There
cos(omega t) - (zeta/s) sin(omega t) = -1 exactly, so with zeta = cos(phi):
    e = exp(-2 phi/tan phi),          omega0 t_end = 2 phi/sin phi      (zeta < 1),
    e = exp(-2),                      omega0 t_end = 2                  (zeta = 1),
    e = exp(-2 a/tanh a),             omega0 t_end = 2 a/sinh a         (zeta = cosh a > 1).
e(zeta) falls monotonically from 1 to 0, passing exp(-2) = 0.1353 at critical damping, so
every e in (0, 1] is reachable (e < exp(-2) only overdamped, e ~ 1/(4 zeta^2) as zeta grows).
Without the clamp (force allowed to pull): e = exp(-pi zeta/s), zeta = -ln e/sqrt(pi^2 + ln^2 e).

Hertz with the speed-independent Tsuji dashpot (Tsuji, Tanaka & Ishida 1992, Powder Technol.
71:239; Antypov & Elliott 2011, EPL 94:50004; verification group A2, A3):
    m* delta'' = -F,  F = k_h delta^{3/2} + c_h sqrt(m* k_h) delta^{1/4} delta',
    k_h = (4/3) E* sqrt(R*).
Scaling delta = delta* x, t = t* tau with delta* = (m* v^2/k_h)^{2/5}, t* = delta*/v gives
    m* v^2/delta* x'' = -k_h delta*^{3/2} [x^{3/2} + c_h sqrt(m*/k_h) v delta*^{-5/4} x^{1/4} x'],
and since m* v^2/delta* = k_h delta*^{3/2} and sqrt(m*/k_h) v = delta*^{5/4}:
    x'' = -x^{3/2} - c_h x^{1/4} x',  x(0) = 0,  x'(0) = 1,
so e depends on c_h alone. In the phase plane (y = x^{5/4}, w = x') this reads
w dw/dy = -(4/5)(y + c_h w), ending at y + c_h w = 0; with y = (sqrt5/2) Y it is exactly the
clamped linear problem w dw/dY = -(Y + 2 zeta w), ending at Y + 2 zeta w = 0, zeta = c_h/sqrt5.
Restitution is a phase-plane quantity, hence exactly
    e_Hertz(c_h) = e_linear,clamped(zeta = c_h/sqrt5),   c_h = sqrt5 zeta(e),
so the calibration is closed-form (e = exp(-2) at c_h = sqrt5, e ~ 5/(4 c_h^2) for large c_h).
Durations are not preserved by that map: the contact time comes from integrating the
dimensionless ODE (sphere_cli.kernels.restitution), which also cross-checks e(c_h) to ~1e-12.
Elastic contact time: t_c = 2.9433 delta_max/v, delta_max = (5/4)^{2/5} delta*; the constant
is (4/5) sqrt(pi) Gamma(2/5)/Gamma(9/10).
"""

import functools
import math

from ..kernels.restitution import hertz_contact_dimensionless
from ..kernels.restitution import hertz_restitution as _hertz_restitution_kernel

#: Restitution of the clamped linear contact at critical damping (zeta = 1).
LINEAR_CRITICAL_RESTITUTION = math.exp(-2.0)

#: t_c v / delta_max of the elastic Hertz impact: (4/5) sqrt(pi) Gamma(2/5)/Gamma(9/10).
HERTZ_ELASTIC_CONTACT_TIME_FACTOR = 0.8 * math.sqrt(math.pi) * math.gamma(0.4) / math.gamma(0.9)

_HERTZ_STEP = 2.0e-3  # dimensionless RK4 step at c_h <= 1; e is then accurate to ~1e-12
_SQRT5 = math.sqrt(5.0)


def _check_restitution(e: float) -> float:
    e = float(e)
    if not (0.0 < e <= 1.0):
        raise ValueError(f"restitution {e!r} must lie in (0, 1]")
    return e


def _bisect_increasing(func, target: float, lo: float, hi: float) -> float:
    """Root of func(x) = target for func increasing on [lo, hi], to the last bit."""
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if func(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _clamped_log_decrement(zeta: float) -> float:
    """-ln e of the clamped linear contact as a function of zeta >= 0."""
    if zeta <= 0.0:
        return 0.0
    if zeta < 1.0:
        return 2.0 * math.acos(zeta) * zeta / math.sqrt((1.0 - zeta) * (1.0 + zeta))
    if zeta == 1.0:
        return 2.0
    a = math.acosh(zeta)
    return 2.0 * a / math.tanh(a)


def linear_restitution(zeta: float, clamped: bool = True) -> float:
    """Coefficient of restitution of the linear spring-dashpot with damping ratio zeta.

    clamped: force max(0, k delta + c delta') (contact ends at zero force); otherwise the
    textbook e = exp(-pi zeta/sqrt(1 - zeta^2)), which is 0 for zeta >= 1 (no separation)."""
    zeta = float(zeta)
    if not zeta >= 0.0:
        raise ValueError(f"damping ratio {zeta!r} must be >= 0")
    if clamped:
        return math.exp(-_clamped_log_decrement(zeta))
    if zeta >= 1.0:
        return 0.0
    return math.exp(-math.pi * zeta / math.sqrt((1.0 - zeta) * (1.0 + zeta)))


def linear_damping_ratio_unclamped(e: float) -> float:
    """Textbook zeta = -ln e/sqrt(pi^2 + ln^2 e), exact only if the force may turn attractive."""
    e = _check_restitution(e)
    if e == 1.0:
        return 0.0
    log_e = math.log(e)
    return -log_e / math.sqrt(math.pi**2 + log_e**2)


def linear_damping_ratio(e: float, *, allow_overdamped: bool = True) -> float:
    """Damping ratio zeta = c/(2 sqrt(k m*)) for which the clamped linear contact rebounds with
    restitution e. Any e in (0, 1] is reachable; e < exp(-2) = 0.1353 needs zeta > 1, which
    allow_overdamped=False refuses with a ValueError. e = 1 gives exactly 0."""
    e = _check_restitution(e)
    if e == 1.0:
        return 0.0
    target = -math.log(e)
    if target < 2.0:
        return _bisect_increasing(_clamped_log_decrement, target, 0.0, 1.0)
    if not allow_overdamped:
        raise ValueError(
            f"restitution {e:g} is below the smallest the clamped linear contact can reach "
            f"without overdamping (exp(-2) = {LINEAR_CRITICAL_RESTITUTION:.4f} at zeta = 1)"
        )
    if target == 2.0:
        return 1.0
    # overdamped branch in a = acosh(zeta): 2a/tanh(a) is increasing and exceeds 2a
    a = _bisect_increasing(lambda a: 2.0 * a / math.tanh(a), target, 0.0, 0.5 * target + 1.0)
    return math.cosh(a)


def linear_contact_time(k: float, m_eff: float, zeta: float, clamped: bool = True) -> float:
    """Duration [s] of a linear spring-dashpot contact, stiffness k [N/m], reduced mass m_eff [kg].

    clamped: until the force reaches zero (finite for every zeta); otherwise until the overlap
    returns to zero, pi/(omega0 sqrt(1 - zeta^2)), infinite for zeta >= 1."""
    if not (k > 0.0 and m_eff > 0.0):
        raise ValueError(f"stiffness {k!r} and mass {m_eff!r} must be positive")
    zeta = float(zeta)
    if not zeta >= 0.0:
        raise ValueError(f"damping ratio {zeta!r} must be >= 0")
    omega0 = math.sqrt(k / m_eff)
    if not clamped:
        if zeta >= 1.0:
            return math.inf
        return math.pi / (omega0 * math.sqrt((1.0 - zeta) * (1.0 + zeta)))
    if zeta < 1.0:
        return 2.0 * math.acos(zeta) / (omega0 * math.sqrt((1.0 - zeta) * (1.0 + zeta)))
    if zeta == 1.0:
        return 2.0 / omega0
    a = math.acosh(zeta)
    return 2.0 * a / (omega0 * math.sinh(a))


def hertz_stiffness(e_eff: float, r_eff: float) -> float:
    """k_h = (4/3) E* sqrt(R*) [N/m^{3/2}] of the Hertz law F = k_h delta^{3/2}."""
    return 4.0 / 3.0 * e_eff * math.sqrt(r_eff)


def _hertz_step(c_h: float) -> float:
    # the damping acts over tau ~ c_h^{-4/5}; keep as many steps there as at c_h = 1
    return _HERTZ_STEP / max(1.0, c_h) ** 0.8


def hertz_restitution(c_h: float) -> float:
    """Restitution of the clamped Hertz contact with dimensionless Tsuji damping c_h >= 0
    (closed form: the clamped linear restitution at zeta = c_h/sqrt5)."""
    c_h = float(c_h)
    if not c_h >= 0.0:
        raise ValueError(f"Hertz damping coefficient {c_h!r} must be >= 0")
    return linear_restitution(c_h / _SQRT5)


def hertz_restitution_integrated(c_h: float) -> float:
    """hertz_restitution by direct RK4 integration of the dimensionless ODE (a check, ~1e-12)."""
    c_h = float(c_h)
    if not c_h >= 0.0:
        raise ValueError(f"Hertz damping coefficient {c_h!r} must be >= 0")
    return float(_hertz_restitution_kernel(c_h, _hertz_step(c_h)))


@functools.lru_cache(maxsize=256)
def hertz_damping_coefficient(e: float) -> float:
    """Dimensionless c_h of F = k_h delta^{3/2} + c_h sqrt(m* k_h) delta^{1/4} delta' (clamped at
    0) that gives restitution e at every impact speed: sqrt5 times the clamped linear zeta.
    Every e in (0, 1] is reachable; e = 1 gives exactly 0."""
    return _SQRT5 * linear_damping_ratio(e)


def hertz_contact_time(m_eff: float, k_h: float, v_impact: float, c_h: float = 0.0) -> float:
    """Duration [s] of a clamped Hertz impact at normal speed v_impact [m/s]: tau_end delta*/v
    with delta* = (m* v^2/k_h)^{2/5}; for c_h = 0 this is 2.9433 delta_max/v."""
    if not (m_eff > 0.0 and k_h > 0.0 and v_impact > 0.0):
        raise ValueError("mass, Hertz stiffness and impact speed must be positive")
    c_h = float(c_h)
    if not c_h >= 0.0:
        raise ValueError(f"Hertz damping coefficient {c_h!r} must be >= 0")
    delta_star = (m_eff * v_impact**2 / k_h) ** 0.4
    _e, tau_end, _x_max = hertz_contact_dimensionless(c_h, _hertz_step(c_h))
    return float(tau_end) * delta_star / v_impact
