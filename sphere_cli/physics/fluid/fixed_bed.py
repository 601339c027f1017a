"""A porous bed held in place, given by its porosity (`[fluid.bed]` of a Navier-Stokes case
without particles): the porosity field of the fluid cells, and the drag of the bed on the fluid.

The bed is the cell-averaged drag of the sphere documentation (kernels/fluid/drag.py
`cell_drag`): per unit volume (1 - phi) k(phi, d, |u|) u with the grain diameter d and the law of
fluid.drag, implicit in the fluid velocity (stable at any drag relaxation time), and in
formulation B with the pressure-gradient force on the solid, -(1 - phi) grad p, exchanged too. The
porosity does not change (its rate is 0).
"""

from __future__ import annotations

import numpy as np

from ...kernels.fluid.drag import cell_drag
from .drag import LAWS
from .fields import cell_expression, read_grid_file


class FixedBed:
    def __init__(self, config, solver, drag_config, density, viscosity, exchanged: bool, loaded):
        """config: the FixedBed table; solver: the NavierStokesSolver (its grid); drag_config: the
        DragConfig (law, porosity floor); density [kg/m^3], viscosity [Pa s] of the fluid;
        exchanged: formulation B with the pressure-gradient force; loaded: the LoadedCase, for
        errors naming the key."""
        key = ("fluid", "bed")
        grid = solver.grid
        shape = tuple(grid.shape)
        where = (*key, "file" if config.file is not None else "porosity")
        if config.file is not None:
            phi = read_grid_file(config.file, {"porosity": shape}, where, loaded, True)["porosity"]
        elif isinstance(config.porosity, str):
            phi = cell_expression(solver, config.porosity, where, loaded)
        else:
            phi = np.full(shape, float(config.porosity))
        z = grid.centres(2).reshape(1, 1, -1)
        inside = np.ones(shape, dtype=bool)  # none empty: config/fluid_navier_stokes.py case_problems
        if config.lower is not None:
            inside &= z >= config.lower
        if config.upper is not None:
            inside &= z <= config.upper
        self.porosity = np.where(inside, phi, 1.0)
        floor = float(drag_config.porosity_floor)
        bad = ~((self.porosity >= floor) & (self.porosity <= 1.0))
        if bad.any():
            i, j, k = (int(n) for n in np.argwhere(bad)[0])
            point = ", ".join(f"{grid.centres(a)[n]:.6g}" for a, n in enumerate((i, j, k)))
            value = float(self.porosity[i, j, k])
            raise loaded.error(
                where,
                f"porosity {value!r} at fluid cell ({i}, {j}, {k}) at ({point}) m; expected between "
                f"fluid.drag.porosity_floor = {floor} and 1",
            )
        self.diameter = np.where(inside, float(config.diameter), 0.0).reshape(-1)
        self.at_rest = np.zeros((grid.cell_count, 3))
        self.law = LAWS[drag_config.law]
        self.floor = floor
        self.density = float(density)
        self.viscosity = float(viscosity)
        self.exchanged = bool(exchanged)

    def impose(self, fs) -> None:
        """The bed's porosity in the fluid state, unchanging."""
        fs.porosity[...] = self.porosity
        fs.porosity_rate[...] = 0.0

    def forcing(self, fs) -> None:
        """fs.f_i and fs.k_drag of the bed for the next fluid step, at the fluid velocity now."""
        cell_drag(
            self.law, self.density, self.viscosity, self.floor, fs.v.reshape(-1, 3), fs.porosity.reshape(-1),
            self.diameter, self.at_rest, fs.grad_p.reshape(-1, 3), self.exchanged, fs.f_i.reshape(-1, 3),
            fs.k_drag.reshape(-1),
        )  # fmt: skip
