"""Solver of the symmetric cell-centred system c_i x_i - div(a grad x)_i = b_i on a FluidGrid
(kernels/fluid/poisson.py has the discretisation), shared by the fluid models: the pressure Poisson
equation of Navier-Stokes (div(phi grad eps) = phi f: c = 0, a = phi) and the implicit pore
pressure step of Darcy (multiplied through so that it stays symmetric: c = beta_f phi mu / dt,
a = k).

Methods:
- "pcg": conjugate gradient, preconditioned by one geometric multigrid V-cycle (`Multigrid`)
  where the cell counts allow coarsening to at most 4096 cells, else by the diagonal (Jacobi)
  of A. On the 64^3 pressure problem: 14 iterations and 0.12 s against 297 iterations and
  0.45 s with the diagonal alone (one thread; docs/performance.md);
- "jacobi": the reference's Jacobi iteration (sphere-fluid-particle-interaction.md), kept to
  compare accuracy and time. It cannot converge on a singular system (the eigenvalue -1 of
  its iteration matrix on a bipartite grid) and then reports converged = False.
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

from ...kernels.fluid.poisson import (
    apply_operator,
    cg_step,
    coarsen_coefficients,
    column_dots,
    column_squares,
    column_sums,
    jacobi_smooth,
    jacobi_sweep,
    new_direction,
    ordered_sum,
    precondition,
    prepare_system,
    prolong_add,
    residual,
    restrict,
    shift,
)
from .grid import FluidGrid

METHODS = ("pcg", "jacobi")
PRECONDITIONERS = ("multigrid", "jacobi")
# multigrid V-cycle: damped Jacobi smoothing (weight 6/7, the best smoothing factor of the 3D
# 7-point stencil), two sweeps before and after the coarse correction, 40 on the coarsest level;
# coarsening stops at 64 cells, and a grid whose coarsest level would keep more than 4096 cells
# (cell counts with few factors of 2) uses the diagonal preconditioner instead
SMOOTHING_WEIGHT = 6.0 / 7.0
SWEEPS = 2
COARSEST_SWEEPS = 40
COARSEST_TARGET = 64
COARSEST_LIMIT = 4096
BOUNDARIES = ("dirichlet", "no-flux")
TINY = np.finfo(np.float64).tiny
RESCALE_EXPONENT = 100  # a right-hand side norm outside 2^-100 .. 2^100 is rescaled


@dataclass(frozen=True)
class PoissonResult:
    iterations: int
    residual: float  # ||b - A x|| / max(||b||, tiny) of the returned x [-]
    converged: bool
    mean_removed: float = 0.0  # singular case: the mean of b taken out (0 for a compatible b)


class _Level:
    """One coarse level: its shape, the coarsening factors from the level above, coefficients,
    diagonal and work arrays."""

    def __init__(self, shape, factors, ih2):
        self.shape = shape
        self.factors = factors
        self.ih2 = ih2
        nx, ny, nz = shape
        self.c, self.diag, self.inv_diag, self.x, self.b, self.r, self.tmp = (
            np.zeros(shape) for _ in range(7)
        )
        self.ax, self.ay, self.az = (
            np.zeros((nx + 1, ny, nz)),
            np.zeros((nx, ny + 1, nz)),
            np.zeros((nx, ny, nz + 1)),
        )
        self.partial = np.zeros(nx * ny)


class Multigrid:
    """Geometric multigrid V-cycle z = M^-1 r for the preconditioned conjugate gradient: cells
    merged in pairs along every axis with an even count of at least 4, coefficients re-discretised
    (means of the fine ones), restriction by averaging and prolongation by injection (a multiple
    of its transpose), the same damped Jacobi sweeps before and after the coarse correction:
    M is symmetric positive definite, as CG needs."""

    def __init__(self, grid: FluidGrid, flags):
        self.flags = flags  # periodic_x, periodic_y, dirichlet_bottom, dirichlet_top (uint8)
        shape = tuple(grid.shape)
        ih2 = 1.0 / np.asarray(grid.spacing, dtype=np.float64) ** 2
        self.levels: list[_Level] = []
        while int(np.prod(shape)) > COARSEST_TARGET:
            factors = tuple(2 if n % 2 == 0 and n >= 4 else 1 for n in shape)
            if factors == (1, 1, 1):
                break
            shape = tuple(n // f for n, f in zip(shape, factors, strict=True))
            ih2 = ih2 / np.asarray(factors, dtype=np.float64) ** 2
            self.levels.append(_Level(shape, factors, ih2))
        self.usable = int(np.prod(shape)) <= COARSEST_LIMIT and bool(self.levels)
        self.grid = grid
        fine = grid.shape
        self.fine_x, self.fine_tmp, self.fine_r = (np.zeros(fine) for _ in range(3))
        self.fine_partial = np.zeros(fine[0] * fine[1])

    def update_spacing(self) -> None:
        """Take the grid's current spacing (a grid following the top wall changes it)."""
        ih2 = 1.0 / self.grid.spacing**2
        for level in self.levels:
            ih2 = ih2 / np.asarray(level.factors, dtype=np.float64) ** 2
            level.ih2[:] = ih2

    def describe(self) -> str:
        shapes = " -> ".join("x".join(str(n) for n in level.shape) for level in self.levels)
        return f"multigrid V-cycle ({len(self.levels) + 1} levels, coarsest {shapes.split(' -> ')[-1]})"

    def setup(self, c, ax, ay, az):
        """Coarse coefficients and diagonals from the fine ones (once per solve)."""
        px, py, db, dt = self.flags
        above = (c, ax, ay, az)
        for level in self.levels:
            fx, fy, fz = level.factors
            coarsen_coefficients(*above, fx, fy, fz, level.c, level.ax, level.ay, level.az)
            prepare_system(
                level.b, level.c, level.ax, level.ay, level.az, px, py, db, dt, 0.0, 0.0, level.ih2,
                level.b, level.diag, level.inv_diag, level.partial,
            )  # fmt: skip
            above = (level.c, level.ax, level.ay, level.az)

    def apply(self, r, z, fine):
        """z = M^-1 r; fine = (diag, inv_diag, ax, ay, az, ih2) of the fine operator."""
        self._cycle(-1, r, z, fine)

    def _smooth(self, rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, sweeps):
        px, py = self.flags[0], self.flags[1]
        for _ in range(sweeps // 2):
            jacobi_smooth(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, SMOOTHING_WEIGHT, tmp)
            jacobi_smooth(rhs, tmp, inv_diag, diag, ax, ay, az, px, py, ih2, SMOOTHING_WEIGHT, x)

    def _cycle(self, index, rhs, x, fine):
        if index < 0:
            diag, inv_diag, ax, ay, az, ih2 = fine
            tmp, res, partial = self.fine_tmp, self.fine_r, self.fine_partial
        else:
            level = self.levels[index]
            diag, inv_diag, ax, ay, az, ih2 = (
                level.diag,
                level.inv_diag,
                level.ax,
                level.ay,
                level.az,
                level.ih2,
            )
            tmp, res, partial = level.tmp, level.r, level.partial
        x[...] = 0.0
        if index == len(self.levels) - 1:
            self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, COARSEST_SWEEPS)
            return
        self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, SWEEPS)
        px, py = self.flags[0], self.flags[1]
        residual(rhs, x, diag, ax, ay, az, px, py, ih2, res, partial)
        coarse = self.levels[index + 1]
        restrict(res, *coarse.factors, coarse.b)
        self._cycle(index + 1, coarse.b, coarse.x, fine)
        prolong_add(coarse.x, *coarse.factors, x)
        self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, SWEEPS)


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
        preconditioner: str = "multigrid",
    ):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {PRECONDITIONERS}, got {preconditioner!r}")
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
        self.multigrid = None
        if method == "pcg" and preconditioner == "multigrid":
            flags = (self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top)
            multigrid = Multigrid(grid, flags)
            self.multigrid = multigrid if multigrid.usable else None

    def update_spacing(self) -> None:
        """Take the grid's current spacing: call after grid.set_height (a grid that follows the
        top wall); the coefficients are rebuilt by every solve."""
        self.ih2[:] = 1.0 / self.grid.spacing**2
        if self.multigrid is not None:
            self.multigrid.update_spacing()

    def describe(self) -> str:
        if self.method == "jacobi":
            name = "Jacobi iteration"
        elif self.multigrid is not None:
            name = f"conjugate gradient preconditioned with a {self.multigrid.describe()}"
        else:
            name = "conjugate gradient, Jacobi-preconditioned"
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
        face_arrays(), kernels/fluid/poisson.py says which face is which); bottom_value/top_value
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
        if rhs_norm == 0.0 and not self.rhs.any():
            x[:] = 0.0
            return PoissonResult(0, 0.0, True, mean_removed)
        # a right-hand side far from unit size (an incremental pressure that has settled decays
        # towards 1e-300) is scaled by a power of two, exactly, taken from its largest value, so
        # that the iteration's sums of squares neither underflow nor overflow
        rescale = not (2.0**-RESCALE_EXPONENT <= rhs_norm <= 2.0**RESCALE_EXPONENT)
        if rescale:
            exponent = math.frexp(float(np.abs(self.rhs).max()))[1]
            np.ldexp(self.rhs, -exponent, out=self.rhs)
            np.ldexp(x, -exponent, out=x)
            column_squares(self.rhs, self.part_a)
            rhs_norm = math.sqrt(ordered_sum(self.part_a))
        scale = 1.0 / max(rhs_norm, TINY)
        if self.method == "pcg":
            iterations, res = self._pcg(x, c, ax, ay, az, singular, scale)
        else:
            iterations, res = self._jacobi(x, ax, ay, az, scale)
        if singular:
            shift(x, self._mean(x))
        if rescale:
            np.ldexp(x, exponent, out=x)
        return PoissonResult(iterations, res, res <= self.tolerance, mean_removed)

    def explicit_step(self, x, b, c, ax, ay, az, bottom_value: float = 0.0, top_value: float = 0.0) -> None:
        """One forward-Euler step of the system that solve() would take one backward-Euler step
        of: with A = c + (the face and boundary terms), c (x' - x) = b - A x, so x += (b - A x)/c
        in place (c > 0 everywhere; no cell may have been eliminated into c)."""
        prepare_system(
            b, c, ax, ay, az, self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top,
            float(bottom_value), float(top_value), self.ih2, self.rhs, self.diag, self.inv_diag, self.part_a,
        )  # fmt: skip
        self._true_residual(x, ax, ay, az)
        np.divide(self.r, c, out=self.r)
        x += self.r

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

    def _pcg(self, x, c, ax, ay, az, singular, scale):
        n = x.size
        iterations = 0
        res = self._true_residual(x, ax, ay, az) * scale
        fine = (self.diag, self.inv_diag, ax, ay, az, self.ih2)
        if self.multigrid is not None:
            self.multigrid.setup(c, ax, ay, az)
        # restarted from the true residual if the recursively updated one drifted from it
        while res > self.tolerance and iterations < self.max_iterations:
            precondition(self.r, self.inv_diag, self.z, self.part_b, self.part_c)
            self._multigrid(fine)
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
                self._multigrid(fine)
                rz_new = ordered_sum(self.part_b)
                z_mean = ordered_sum(self.part_c) / n if singular else 0.0
                new_direction(self.p, self.z, rz_new / rz, z_mean)
                rz = rz_new
            res = self._true_residual(x, ax, ay, az) * scale
        return iterations, res

    def _multigrid(self, fine) -> None:
        """Replace the diagonal preconditioner's z (and its partial sums) by the V-cycle's."""
        if self.multigrid is not None:
            self.multigrid.apply(self.r, self.z, fine)
            column_dots(self.r, self.z, self.part_b, self.part_c)

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
