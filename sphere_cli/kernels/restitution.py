"""Dimensionless damped Hertz impact, integrated to the end of contact (restitution calibration).

Law: Hertz spring with the Tsuji-type dashpot whose restitution does not depend on impact
speed (Tsuji, Tanaka & Ishida 1992, Powder Technol. 71:239; exact e(c) discussed by
Antypov & Elliott 2011, EPL 94:50004), clamped so it never attracts:
    m* delta'' = -F,  F = max(0, k_h delta^{3/2} + c sqrt(m* k_h) delta^{1/4} delta').
With delta = delta* x, t = (delta*/v) tau, delta* = (m* v^2/k_h)^{2/5} this is
    x'' = -x^{3/2} - c x^{1/4} x',  x(0) = 0, x'(0) = 1,
so e = |x'(tau_end)| depends on c only. The contact ends where the force vanishes
(x^{5/4} + c x' = 0, before x returns to 0 when c > 0; at x = 0 when c = 0).

Classical RK4. The right-hand side is not smooth at x = 0 (x^{1/4}), so the first stretch
tau in [0, T], T = (1/4) min(1, c^{-4/5}) (the damping acts over tau ~ c^{-4/5}), uses the
graded mesh tau_k = T (k/n)^4 with n = 4T/h, which keeps fourth order; the rest uses the
uniform step h. The end of contact (force zero) and the apex (x' = 0) are located on
the cubic Hermite interpolant of the last step. At the end of contact x'' = 0, so the
rebound speed is insensitive to the located end time.
"""

import math

from numba import njit


@njit(cache=True)
def hertz_acceleration(x, v, c):
    """x'' of the dimensionless damped Hertz contact (no clamping; x < 0 gives 0)."""
    if x <= 0.0:
        return 0.0
    return -x * math.sqrt(x) - c * math.sqrt(math.sqrt(x)) * v


@njit(cache=True)
def hertz_end_function(x, v, c):
    """Signed end-of-contact function: x^{5/4} + c x' (x^{5/4} taken odd in x); zero at the end."""
    if x >= 0.0:
        p = x * math.sqrt(math.sqrt(x))
    else:
        p = x * math.sqrt(math.sqrt(-x))
    return p + c * v


@njit(cache=True)
def hermite(y0, d0, y1, d1, h, s):
    """Cubic Hermite interpolant on a step of length h at fraction s in [0, 1]."""
    s2 = s * s
    s3 = s2 * s
    return (
        (2.0 * s3 - 3.0 * s2 + 1.0) * y0
        + (s3 - 2.0 * s2 + s) * h * d0
        + (-2.0 * s3 + 3.0 * s2) * y1
        + (s3 - s2) * h * d1
    )


@njit(cache=True)
def hertz_contact_dimensionless(c, h):
    """Integrate x'' = -x^{3/2} - c x^{1/4} x' from x = 0, x' = 1 with step h until the force
    vanishes. Returns (e, tau_end, x_max): restitution |x'(tau_end)|, contact duration and
    maximum overlap, all dimensionless (multiply by delta*/v and delta*)."""
    x = 0.0
    v = 1.0
    a = hertz_acceleration(x, v, c)
    tau = 0.0
    x_max = 0.0
    graded_span = 0.25 / max(1.0, c) ** 0.8
    n_graded = max(4, int(math.ceil(4.0 * graded_span / h)))
    k = 0
    max_steps = n_graded + int(math.ceil(1000.0 / h))
    for _ in range(max_steps):
        if k < n_graded:
            k += 1
            r = k / n_graded
            step = graded_span * r * r * r * r - tau
        else:
            step = h
        # classical RK4 for (x, v)
        k1v = a
        k2x = v + 0.5 * step * k1v
        k2v = hertz_acceleration(x + 0.5 * step * v, k2x, c)
        k3x = v + 0.5 * step * k2v
        k3v = hertz_acceleration(x + 0.5 * step * k2x, k3x, c)
        k4x = v + step * k3v
        k4v = hertz_acceleration(x + step * k3x, k4x, c)
        x1 = x + step / 6.0 * (v + 2.0 * k2x + 2.0 * k3x + k4x)
        v1 = v + step / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        a1 = hertz_acceleration(x1, v1, c)
        if v > 0.0 and v1 <= 0.0:
            # apex: x' = 0 on the Hermite interpolant of x', then x there
            lo = 0.0
            hi = 1.0
            for _it in range(60):
                mid = 0.5 * (lo + hi)
                if hermite(v, a, v1, a1, step, mid) > 0.0:
                    lo = mid
                else:
                    hi = mid
            x_max = hermite(x, v, x1, v1, step, 0.5 * (lo + hi))
        g1 = hertz_end_function(x1, v1, c)
        if g1 <= 0.0:
            # end of contact inside this step: bisect the end function on the interpolant
            lo = 0.0
            hi = 1.0
            for _it in range(60):
                mid = 0.5 * (lo + hi)
                xm = hermite(x, v, x1, v1, step, mid)
                vm = hermite(v, a, v1, a1, step, mid)
                if hertz_end_function(xm, vm, c) > 0.0:
                    lo = mid
                else:
                    hi = mid
            s = 0.5 * (lo + hi)
            v_end = hermite(v, a, v1, a1, step, s)
            if x_max == 0.0:
                x_max = max(x, x1)
            return -v_end, tau + s * step, x_max
        x = x1
        v = v1
        a = a1
        tau += step
    return math.nan, math.nan, x_max


@njit(cache=True)
def hertz_restitution(c, h):
    """Restitution e(c) of the clamped damped Hertz contact, dimensionless step h."""
    e, _tau, _xmax = hertz_contact_dimensionless(c, h)
    return e
