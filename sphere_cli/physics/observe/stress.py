"""Granular stress tensor (on the observables schedule only): contact virial plus
kinetic part, for the whole sample and per horizontal layer; pressure and the effective friction.
See kernels/observe/stress.py for the formula. Compression is positive (soil-mechanics convention):
a sample squeezed along z has sigma_zz > 0.

Effective friction: tau/sigma_n with sigma_n = sigma_zz and tau = -(sigma_zs + sigma_sz)/2, s the
shear direction (x or y): the shear traction the material above a horizontal plane exerts on the
material below, along +s (positive when a top wall drags the sample along +s).
"""

from __future__ import annotations

import numpy as np

from ...kernels.observe.stress import contact_moments, layer_sums
from ...state import State
from .energy_budget import wall_velocity
from .structure import Region

UNITS = {
    "stress": "Pa",
    "pressure": "Pa",
    "effective_friction": "",
}
PROFILE_UNITS = {
    "layer_center": "m",
    "packing_fraction_profile": "",
    "stress_profile": "Pa",
    "velocity_profile": "m s-1",
}


class StressProbe:
    """Scratch arrays of the stress measurement, allocated once."""

    def __init__(self, state: State, contact):
        n = state.particles.count
        self.contact = contact  # its table may change between stages
        self.scratch = np.zeros((n, 1, 3))
        self.moment = np.zeros((n, 3, 3))
        w = state.walls
        walls = 0 if w is None else w.axis.shape[0]
        self.still = np.zeros((walls, 3))
        self.no_walls = (np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
        self.no_wall_rows = (np.zeros((0, 1, 6)), np.zeros((n, 0, 3)))

    def moments(self, state: State) -> np.ndarray:
        p, box, nl, w = state.particles, state.box, state.neighbors, state.walls
        if w is None:
            walls, rows = self.no_walls, self.no_wall_rows
        else:
            predicted = getattr(w, "vel_pred", None)
            walls = (
                w.axis,
                w.sign,
                w.coord,
                wall_velocity(w, self.still) if predicted is None else predicted,
            )
            rows = (w.table, w.hist)
        contact_moments(
            p.pos,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.mass,
            p.inv_mass,
            p.material,
            nl.nbr,
            nl.nbr_count,
            nl.start,
            nl.hist,
            self.contact.table,
            self.contact.law_code,
            box.length,
            box.periodic,
            *walls,
            *rows,
            self.scratch,
            self.moment,
        )
        return self.moment

    def measure(self, state: State, sample: Region, layers: int, shear_axis: int) -> tuple[dict, dict]:
        """(sample observables, per-layer arrays) of the stress, in the units of UNITS."""
        p = state.particles
        moment = self.moments(state)
        z0 = float(sample.lower[2])
        height = float(sample.upper[2] - sample.lower[2])
        dz = height / layers
        count = np.zeros(layers, dtype=np.int64)
        momentum = np.zeros((layers, 3))
        mass = np.zeros(layers)
        virial = np.zeros((layers, 3, 3))
        kinetic = np.zeros((layers, 3, 3))
        layer_sums(p.pos, p.vel, p.mass, moment, z0, dz, layers, count, momentum, mass, virial, kinetic)
        area = float(np.prod(sample.upper[:2] - sample.lower[:2]))
        sigma = (kinetic.sum(axis=0) - virial.sum(axis=0)) / sample.volume
        profile = (kinetic - virial) / (area * dz)
        velocity = np.divide(momentum, mass[:, None], out=np.zeros_like(momentum), where=mass[:, None] > 0)
        tau = -0.5 * (sigma[2, shear_axis] + sigma[shear_axis, 2])
        values = {
            "stress": sigma,
            "pressure": float(np.trace(sigma) / 3.0),
            "effective_friction": float(tau / sigma[2, 2]) if sigma[2, 2] != 0.0 else float("nan"),
        }
        profiles = {
            "layer_center": z0 + dz * (np.arange(layers) + 0.5),
            "stress_profile": profile,
            "velocity_profile": velocity,
        }
        return values, profiles
