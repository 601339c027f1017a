"""Solver of the symmetric cell-centred system c_i x_i - div(a grad x)_i = b_i on a FluidGrid
(kernels/poisson.py has the discretisation), shared by the fluid models: the pressure Poisson
equation of Navier-Stokes (div(phi grad eps) = phi f: c = 0, a = phi) and the implicit pore
pressure step of Darcy (multiplied through so that it stays symmetric: c = beta_f phi mu / dt,
a = k).

Methods:
- "pcg": conjugate gradient preconditioned with the diagonal (Jacobi) of A;
- "jacobi": the reference's Jacobi iteration (sphere-fluid-particle-interaction.md), kept to
  compare accuracy and time.
Both stop when the residual ||b - A x||_2 / max(||b||_2, tiny) (b with the Dirichlet face
values moved over) is at most the tolerance; it is defined whatever b and x are (the
reference's normalised residual divides by x and is not). A zero right-hand side gives x = 0
exactly, without iterating. When c = 0 everywhere and no boundary is Dirichlet the system is
singular (x is defined up to a constant): the mean of b is removed (a compatible b has none;
the amount is reported) and the zero-mean solution is returned.

The solver object holds all its scratch arrays: a solve allocates nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernels.poisson import (
    apply_operator,
    cg_step,
    column_squares,
    column_sums,
    jacobi_sweep,
    new_direction,
    ordered_sum,
    precondition,
    prepare_system,
    residual,
    shift,
)
from .fluid_grid import FluidGrid

METHODS = ("pcg", "jacobi")
BOUNDARIES = ("dirichlet", "no-flux")
TINY = np.finfo(np.float64).tiny


@dataclass(frozen=True)
class PoissonResult:
    iterations: int
    residual: float  # ||b - A x|| / max(||b||, tiny) of the returned x [-]
    converged: bool
    mean_removed: float = 0.0  # singular case: the mean of b taken out (0 for a compatible b)


class PoissonSolver:
    """Solve c x - div(a grad x) = b on `grid` (x/y periodic or no-flux as grid.periodic; z
    never periodic) with the bottom and top boundaries each "dirichlet" or "no-flux"."""

    def __init__(
        self,
        grid: FluidGrid,
        bottom: str,
        top: str,
        method: str = "pcg",
        tolerance: float = 1e-8,
        max_iterations: int = 100_000,
    ):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        for name, value in (("bottom", bottom), ("top", top)):
            if value not in BOUNDARIES:
                raise ValueError(f"{name} must be one of {BOUNDARIES}, got {value!r}")
        if grid.periodic[2]:
            raise ValueError("the Poisson solver's z axis cannot be periodic")
        if not tolerance > 0:
            raise ValueError(f"tolerance must be positive, got {tolerance}")
        self.grid = grid
        self.method = method
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.periodic_x = np.uint8(bool(grid.periodic[0]))
        self.periodic_y = np.uint8(bool(grid.periodic[1]))
        self.dirichlet_bottom = np.uint8(bottom == "dirichlet")
        self.dirichlet_top = np.uint8(top == "dirichlet")
        self.ih2 = 1.0 / np.asarray(grid.spacing, dtype=np.float64) ** 2
        shape = tuple(grid.shape)
        self.rhs, self.diag, self.inv_diag, self.r, self.z, self.p, self.q = (
            np.zeros(shape) for _ in range(7)
        )
        columns = shape[0] * shape[1]
        self.part_a, self.part_b, self.part_c = (np.zeros(columns) for _ in range(3))

    def describe(self) -> str:
        name = "conjugate gradient, Jacobi-preconditioned" if self.method == "pcg" else "Jacobi iteration"
        return f"{name}, tolerance {self.tolerance:g}"

    def face_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zeroed face-coefficient arrays of the shapes solve() expects (allocate once)."""
        nx, ny, nz = self.grid.shape
        return np.zeros((nx + 1, ny, nz)), np.zeros((nx, ny + 1, nz)), np.zeros((nx, ny, nz + 1))

    def solve(
        self,
        x: np.ndarray,
        b: np.ndarray,
        c: np.ndarray,
        ax: np.ndarray,
        ay: np.ndarray,
        az: np.ndarray,
        bottom_value: float = 0.0,
        top_value: float = 0.0,
    ) -> PoissonResult:
        """Solve in place: x holds the first guess and receives the solution. b, c (>= 0) are
        cell fields (nx, ny, nz); ax, ay, az the face coefficients (a > 0; shapes as
        face_arrays(), kernels/poisson.py says which face is which); bottom_value/top_value
        the Dirichlet values at the bottom/top boundary face (unused for no-flux)."""
        prepare_system(
            b, c, ax, ay, az, self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top,
            float(bottom_value), float(top_value), self.ih2, self.rhs, self.diag, self.inv_diag, self.part_a,
        )  # fmt: skip
        singular = not (self.dirichlet_bottom or self.dirichlet_top) and not c.any()
        mean_removed = 0.0
        if singular:
            mean_removed = self._mean(self.rhs)
            shift(self.rhs, mean_removed)
            column_squares(self.rhs, self.part_a)
        rhs_norm = math.sqrt(ordered_sum(self.part_a))
        if rhs_norm == 0.0:
            x[:] = 0.0
            return PoissonResult(0, 0.0, True, mean_removed)
        scale = 1.0 / max(rhs_norm, TINY)
        if self.method == "pcg":
            iterations, res = self._pcg(x, ax, ay, az, singular, scale)
        else:
            iterations, res = self._jacobi(x, ax, ay, az, scale)
        if singular:
            shift(x, self._mean(x))
        return PoissonResult(iterations, res, res <= self.tolerance, mean_removed)

    # -- helpers -----------------------------------------------------------------------------

    def _mean(self, field: np.ndarray) -> float:
        column_sums(field, self.part_c)
        return ordered_sum(self.part_c) / field.size

    def _true_residual(self, x, ax, ay, az) -> float:
        residual(
            self.rhs,
            x,
            self.diag,
            ax,
            ay,
            az,
            self.periodic_x,
            self.periodic_y,
            self.ih2,
            self.r,
            self.part_a,
        )
        return math.sqrt(ordered_sum(self.part_a))

    def _pcg(self, x, ax, ay, az, singular, scale):
        n = x.size
        iterations = 0
        res = self._true_residual(x, ax, ay, az) * scale
        # restarted from the true residual if the recursively updated one drifted from it
        while res > self.tolerance and iterations < self.max_iterations:
            precondition(self.r, self.inv_diag, self.z, self.part_b, self.part_c)
            rz = ordered_sum(self.part_b)
            z_mean = ordered_sum(self.part_c) / n if singular else 0.0
            new_direction(self.p, self.z, 0.0, z_mean)
            while iterations < self.max_iterations:
                apply_operator(
                    self.p,
                    self.diag,
                    ax,
                    ay,
                    az,
                    self.periodic_x,
                    self.periodic_y,
                    self.ih2,
                    self.q,
                    self.part_a,
                )
                pq = ordered_sum(self.part_a)
                if not pq > 0.0:
                    return iterations, self._true_residual(x, ax, ay, az) * scale
                alpha = rz / pq
                cg_step(
                    x,
                    self.r,
                    self.p,
                    self.q,
                    alpha,
                    self.inv_diag,
                    self.z,
                    self.part_a,
                    self.part_b,
                    self.part_c,
                )
                iterations += 1
                if math.sqrt(ordered_sum(self.part_a)) * scale <= self.tolerance:
                    break
                rz_new = ordered_sum(self.part_b)
                z_mean = ordered_sum(self.part_c) / n if singular else 0.0
                new_direction(self.p, self.z, rz_new / rz, z_mean)
                rz = rz_new
            res = self._true_residual(x, ax, ay, az) * scale
        return iterations, res

    def _jacobi(self, x, ax, ay, az, scale):
        src, dst = x, self.r
        iterations = 0
        while True:
            jacobi_sweep(
                self.rhs, src, self.diag, self.inv_diag, ax, ay, az,
                self.periodic_x, self.periodic_y, self.ih2, dst, self.part_a,
            )  # fmt: skip
            res = math.sqrt(ordered_sum(self.part_a)) * scale  # of src
            if res <= self.tolerance or iterations >= self.max_iterations:
                break
            iterations += 1
            src, dst = dst, src
        if src is not x:
            x[:] = src
        return iterations, res
