"""The observables of a run: the groups the case lists in
`output.observables.quantities`, computed only when the observables schedule is due.

Each sample is a dict name -> (value, unit); a value is a float or an array (the stress tensor
(3,3), the profiles (layers,), (layers,3) or (layers,3,3)). Groups:
  energy, contacts         physics/observe/energy.py
  packing_fraction,
  coordination             physics/observe/structure.py (interior region: see there)
  stress, profiles         physics/observe/stress.py
  deformation              sample height H (z extent of the sample region) [m] and the dilation
                           (H - H_0)/H_0 against the height at the first sample of the run, or
                           of the current stage with [[stages]] [-];
                           with walls, the shear strain: the upper z wall's displacement along
                           the shear direction relative to the lower wall's, over H_0 [-]
and, always, the observables hook of every module in the scene (physics/module.py): with walls
their positions, velocities, forces and stresses, one row per wall (physics/walls.py); with
stages the index of the current one; with `energy_budget` among the quantities, the budget
(physics/observe/energy_budget.py); with a fluid, the fluid model's own (physics/fluid_plugin.py).
"""

from __future__ import annotations

import logging

import numpy as np

from ...state import State
from ..module import Module
from . import energy, structure
from .stress import PROFILE_UNITS, StressProbe
from .stress import UNITS as STRESS_UNITS

AXES = {"x": 0, "y": 1}


class Observer(Module):
    def __init__(self, scene, config):
        self.scene = scene
        self.config = config
        self.groups = set(config.quantities)
        self.shear_axis = AXES[config.shear_direction]
        radius = scene.state.particles.radius
        self.margin = config.interior_margin * 2.0 * float(radius.max()) if radius.size else 0.0
        self.stress = None
        if self.groups & {"stress", "profiles"}:
            self.stress = StressProbe(scene.state, scene.contact)
        # sample height at the first sample of the run or of the current stage [m] (nan: not
        # measured yet), and that stage's index
        self.reference_height = np.array([np.nan, -1.0])
        self.warned_no_interior = False

    def _warn_if_no_interior(self, sample, interior) -> None:
        """Once a run: a sample too thin for its interior (a shallow bed under the default margin
        of 2 largest diameters at the floor and at the free surface) gives NaN for the interior
        packing fraction and the coordination numbers, which a plot shows as nothing."""
        if self.warned_no_interior or interior.volume > 0.0 or sample.volume == 0.0:
            return
        self.warned_no_interior = True
        extent = sample.upper - sample.lower
        thin = int(np.argmin(np.where(sample.bounded > 0, extent, np.inf)))
        logging.getLogger("sphere.observables").warning(
            "observables at t = %.6g s: the sample is %.4g m thick along %s, and "
            "output.observables.interior_margin = %g largest diameters (%.4g m) from each of its "
            "bounded faces leaves no interior: packing_fraction_interior, coordination, "
            "coordination_no_rattlers and rattler_fraction are NaN while it is so; a smaller "
            "interior_margin measures them",
            self.scene.state.clock.time, extent[thin], "xyz"[thin], self.config.interior_margin, self.margin,
        )  # fmt: skip

    @property
    def name(self) -> str:
        """Stateful (a checkpoint group) only when it measures the deformation."""
        return "observables" if "deformation" in self.groups else ""

    def sample(self) -> dict[str, tuple]:
        scene, state, groups = self.scene, self.scene.state, self.groups
        out: dict[str, tuple] = {}
        if groups:  # none without particles: the modules' own alone (the fluid's)
            self._sample_groups(out)
        for observed in scene.step.observed:
            out.update(observed(state))
        return out

    def _sample_groups(self, out: dict[str, tuple]) -> None:
        """The groups of output.observables.quantities, into `out`."""
        scene, state, groups = self.scene, self.scene.state, self.groups
        for name, value in energy.observables(scene).items():
            if energy.GROUPS[name] in groups:
                out[name] = (value, energy.UNITS[name])
        sample = structure.sample_region(state)
        interior = sample.shrunk(self.margin)
        if groups & {"packing_fraction", "coordination"}:
            self._warn_if_no_interior(sample, interior)
        if "packing_fraction" in groups:
            for name, value in structure.packing_fractions(state, sample, interior).items():
                out[name] = (value, structure.UNITS[name])
        if "coordination" in groups:
            for name, value in structure.coordination(state, scene.contact.table, interior).items():
                out[name] = (value, structure.UNITS[name])
        if self.stress is not None:
            layers = self.config.layers
            values, profiles = self.stress.measure(state, sample, layers, AXES[self.config.shear_direction])
            if "stress" in groups:
                for name, value in values.items():
                    out[name] = (value, STRESS_UNITS[name])
            if "profiles" in groups:
                profiles["packing_fraction_profile"] = structure.layer_fractions(state, sample, layers)
                for name, value in profiles.items():
                    out[name] = (value, PROFILE_UNITS[name])
        if "deformation" in groups:
            height = float(sample.upper[2] - sample.lower[2])
            stage = -1.0 if scene.stages is None else float(scene.stages.index)
            if np.isnan(self.reference_height[0]) or stage != self.reference_height[1]:
                self.reference_height[:] = (height, stage)
            ref = float(self.reference_height[0])
            out["sample_height"] = (height, "m")
            out["dilation"] = ((height - ref) / ref, "")
            if state.walls is not None:
                out["shear_strain"] = (shear_strain(state.walls, self.shear_axis, ref), "")

    def prognostic_state(self, state: State) -> dict:
        return {"reference_height": self.reference_height}

    def restore(self, state: State, arrays: dict) -> None:
        self.reference_height[:] = arrays["reference_height"]

    def start(self) -> None:
        """Nothing measured yet (a resume from a checkpoint that did not record deformation)."""
        self.reference_height[:] = np.nan


def shear_strain(walls, axis: int, height: float) -> float:
    """Displacement of the upper z wall relative to the lower one along the shear axis since
    the start of the run, over the sample height at the first sample [-] (0 without them)."""
    top = bottom = 0.0
    for w, face in enumerate(walls.faces):
        if face == "z+":
            top = float(walls.shift[w, axis])
        elif face == "z-":
            bottom = float(walls.shift[w, axis])
    return (top - bottom) / height
