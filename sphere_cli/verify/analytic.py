"""Analytic solutions the verification cases compare with (verification group A1, A4).

Linear spring-dashpot impact with the force clamped at zero (never attractive), overlap delta
(positive in contact), approach speed v, m* delta'' = -(k delta + c delta') + m* g_n:
    omega0 = sqrt(k/m*), zeta = c/(2 sqrt(k m*)), omega = omega0 sqrt(1 - zeta^2),
    delta(t) = delta_s + exp(-zeta omega0 t) (A cos omega t + B sin omega t),
    delta_s = m* g_n/k, A = -delta_s, B = (v - zeta omega0 delta_s)/omega,
until the force k delta + c delta' returns to zero (Schwager & Poeschel 2007, Granular Matter
9:465); with g_n = 0 this is the A1 solution delta = (v/omega) exp(-zeta omega0 t) sin(omega t),
ending at the clamped contact time of physics/restitution.py. After the contact the bodies
separate at the constant speed e v (no gravity) or fly ballistically (gravity).
"""

from __future__ import annotations

import math

import numpy as np


class DampedImpact:
    """Clamped linear impact, underdamped (zeta < 1), optionally pressed by a constant
    acceleration g_n along the approach (gravity onto a wall)."""

    def __init__(self, k: float, m_eff: float, zeta: float, v: float, g_n: float = 0.0):
        if not 0.0 <= zeta < 1.0:
            raise ValueError(f"damping ratio {zeta!r} must lie in [0, 1)")
        self.k, self.m, self.zeta, self.v, self.g = k, m_eff, zeta, v, g_n
        self.w0 = math.sqrt(k / m_eff)
        self.w = self.w0 * math.sqrt((1.0 - zeta) * (1.0 + zeta))
        self.c = 2.0 * zeta * math.sqrt(k * m_eff)
        self.ds = m_eff * g_n / k
        self.a = -self.ds
        self.b = (v - zeta * self.w0 * self.ds) / self.w
        self.t_end = self._end_time()
        self.delta_end = float(self.overlap(self.t_end))
        self.v_end = float(self.rate(self.t_end))  # d delta/dt at the end (< 0: separating)

    def overlap(self, t):
        t = np.asarray(t, dtype=np.float64)
        decay = np.exp(-self.zeta * self.w0 * t)
        return self.ds + decay * (self.a * np.cos(self.w * t) + self.b * np.sin(self.w * t))

    def rate(self, t):
        t = np.asarray(t, dtype=np.float64)
        decay = np.exp(-self.zeta * self.w0 * t)
        zw = self.zeta * self.w0
        return decay * (
            (-zw * self.a + self.w * self.b) * np.cos(self.w * t)
            + (-zw * self.b - self.w * self.a) * np.sin(self.w * t)
        )

    def force(self, t) -> float:
        """Unclamped contact force k delta + c delta' [N]."""
        return float(self.k * self.overlap(t) + self.c * self.rate(t))

    def _end_time(self) -> float:
        """First root of the force after the touch, bracketed on a fine scan, then bisected."""
        h = math.pi / self.w / 512.0
        t = h
        while self.force(t) > 0.0:
            t += h
        lo, hi = t - h, t
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            if self.force(mid) > 0.0:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    @property
    def peak_overlap(self) -> float:
        t = np.linspace(0.0, self.t_end, 4097)
        return float(self.overlap(t).max())

    def separating_overlap(self, t):
        """delta(t) for all t (no gravity): v t before the touch (t < 0, a gap), the damped
        oscillation in contact, and separation at the exit speed afterwards."""
        t = np.asarray(t, dtype=np.float64)
        inside = self.overlap(np.clip(t, 0.0, self.t_end))
        after = self.delta_end + self.v_end * (t - self.t_end)
        return np.where(t < 0.0, self.v * t, np.where(t <= self.t_end, inside, after))


def bounce_apexes(h0: float, k: float, m: float, zeta: float, g: float, bounces: int) -> np.ndarray:
    """Apex heights [m] (lowest point of the sphere above the wall) after each of `bounces`
    bounces of a sphere dropped from rest at height h0 onto a wall, with gravity acting during
    the contact: the exact solution of the clamped linear model (A4 idealises it as e^{2n} h0)."""
    h = h0
    out = []
    for _ in range(bounces):
        impact = DampedImpact(k, m, zeta, math.sqrt(2.0 * g * h), g)
        up = -impact.v_end
        h = -impact.delta_end + up * up / (2.0 * g)
        out.append(h)
    return np.array(out)


class HertzElasticImpact:
    """Elastic Hertz impact m* delta'' = -k_h delta^{3/2} at approach speed v (Hertz 1882;
    verification group A2): delta = delta* x(t v/delta*), delta* = (m* v^2/k_h)^{2/5}, with
    x'' = -x^{3/2}, x(0) = 0, x'(0) = 1 integrated once by RK4 at a dimensionless step of 1e-3
    (error ~1e-13) and interpolated by cubic Hermite; delta_max = (5/4)^{2/5} delta*,
    t_c = 2.9433 delta_max/v."""

    STEP = 1.0e-3

    def __init__(self, k_h: float, m_eff: float, v: float):
        self.k, self.m, self.v = k_h, m_eff, v
        self.scale = (m_eff * v * v / k_h) ** 0.4
        self.delta_max = 1.25**0.4 * self.scale
        self.force_max = k_h * self.delta_max**1.5
        tau, x, w = self._integrate()
        self.tau, self.x, self.w = tau, x, w
        # the end: x returns to 0 within the last step (Hermite root by bisection)
        self.tau_end = self._root()
        self.t_end = self.tau_end * self.scale / v

    def _integrate(self):
        h = self.STEP

        def acc(x):
            return -(x**1.5) if x > 0.0 else 0.0

        tau, x, w = [0.0], [0.0], [1.0]
        while x[-1] >= 0.0 or len(x) < 3:
            x0, w0 = x[-1], w[-1]
            k1x, k1w = w0, acc(x0)
            k2x, k2w = w0 + 0.5 * h * k1w, acc(x0 + 0.5 * h * k1x)
            k3x, k3w = w0 + 0.5 * h * k2w, acc(x0 + 0.5 * h * k2x)
            k4x, k4w = w0 + h * k3w, acc(x0 + h * k3x)
            x.append(x0 + h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x))
            w.append(w0 + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w))
            tau.append(tau[-1] + h)
        return np.array(tau), np.array(x), np.array(w)

    def _hermite(self, tau):
        tau = np.asarray(tau, dtype=np.float64)
        h = self.STEP
        k = np.clip(np.floor(tau / h).astype(np.int64), 0, self.tau.size - 2)
        s = (tau - self.tau[k]) / h
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        return h00 * self.x[k] + h10 * h * self.w[k] + h01 * self.x[k + 1] + h11 * h * self.w[k + 1]

    def _root(self) -> float:
        lo, hi = self.tau[-2], self.tau[-1]
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            if self._hermite(mid) > 0.0:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    def separating_overlap(self, t):
        """delta(t) [m] for all t: v t before the touch (t < 0), the Hertz history in contact,
        separation at speed v afterwards (elastic)."""
        t = np.asarray(t, dtype=np.float64)
        tau = t * self.v / self.scale
        inside = self.scale * self._hermite(np.clip(tau, 0.0, self.tau_end))
        after = -self.v * (t - self.t_end)
        return np.where(t < 0.0, self.v * t, np.where(t <= self.t_end, inside, after))
