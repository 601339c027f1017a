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

The solver object holds all its scratch arrays: a solve allocates nothing. They and the kernels
that work on them are at a place the solver is given: the processor's (`OnProcessor`,
kernels/fluid/poisson.py) or a GPU's (physics/fluid/device_poisson.py), the same iteration on
either.

Across MPI ranks (`PoissonSolver.split`, a fluid stepped on every rank of a split run) the
conjugate gradient and the multigrid levels whose planes allow it work on slabs of x planes, one
per rank (`Slabs`): each rank updates its own columns, brings in the planes beside its slab
before a stencil reads them, and every sum adds the column partial sums exactly (each rank its
own columns, then one Allreduce of the sum's integer words: kernels/exact_sum.py), so the
iterates, the iteration count and the solution are one rank's, bit for bit. The right-hand
side, the coefficients and the coarse levels the slabs do not fit are computed whole on every
rank; the solution is gathered whole on every rank at the end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ...kernels.exact_sum import WORDS, exact_value
from ...kernels.fluid import poisson as poisson_kernels
from ...kernels.fluid.poisson import diagonal_cg, diagonal_cg_serial, red_black_smooth
from ...kernels.serial import use_serial
from .grid import FluidGrid

METHODS = ("pcg", "jacobi")
PRECONDITIONERS = ("multigrid", "jacobi")
# multigrid V-cycle: two red-black Gauss-Seidel sweeps before the coarse correction (red then
# black) and two after (black then red, the adjoint: the cycle stays symmetric, as CG needs); a
# level that cannot be coloured (an odd cell count along a periodic axis) and the coarsest (40
# sweeps) smooth by damped Jacobi sweeps (weight 6/7, the best smoothing factor of the 3D
# 7-point stencil). Red-black against Jacobi, from zero to 1e-8, one thread (docs/performance.md,
# 2026-12-06): 8 against 14 iterations and 0.055-0.063 against 0.094 s at 64^3, 8 against 12-13
# and 9 against 11-12 ms at 32^3, 7 against 11-12 at 16^3 (the same time); three sweeps took
# 6-7 iterations and as long. Coarsening stops at 64 cells, and a grid whose coarsest level would
# keep more than 4096 cells (cell counts with few factors of 2) uses the diagonal
# preconditioner instead
SMOOTHING_WEIGHT = 6.0 / 7.0
SWEEPS = 2
COARSEST_SWEEPS = 40
COARSEST_TARGET = 64
COARSEST_LIMIT = 4096
# a fluid's grid of fewer cells is solved faster with the diagonal preconditioner (more
# iterations, each a few kernels instead of a V-cycle's dozen calls): from zero to 1e-8, one
# thread, 6^3 0.30 against 0.72 ms, 12^3 1.24 against 1.65, 16^3 2.4 against 2.5, 24^3 10.4
# against 6.1 (docs/performance.md, 2026-12-05 night)
MULTIGRID_FROM = 4096
BOUNDARIES = ("dirichlet", "no-flux")
TINY = np.finfo(np.float64).tiny
RESCALE_EXPONENT = 100  # a right-hand side norm outside 2^-100 .. 2^100 is rescaled
# split across ranks: a slab may hold this many times an even share of the planes, so that more
# multigrid levels are split alike (a level solved whole costs every rank an eighth of the last)
SLAB_IMBALANCE = 1.25


class OnProcessor:
    """Where a solver's fields live and the kernels that work on them: the processor's memory and
    kernels/fluid/poisson.py. A GPU's (physics/fluid/device_poisson.py OnGpu) answers the same
    calls with the same kernels on its own arrays."""

    kernels = poisson_kernels
    fused = True  # whole-grid loops in one compiled call (red_black_smooth, diagonal_cg)
    where = ""  # for describe()

    @staticmethod
    def device_bytes() -> int:
        """The bytes its fields take on a GPU: none here."""
        return 0

    @staticmethod
    def zeros(shape) -> np.ndarray:
        return np.zeros(shape)

    @staticmethod
    def array(values: np.ndarray) -> np.ndarray:
        """A field the kernels take, holding values (here: values itself)."""
        return values

    @staticmethod
    def put(field, values) -> None:
        field[...] = values

    @staticmethod
    def host(field) -> np.ndarray:
        """The field's values in the processor's memory (here: the field itself)."""
        return field

    @staticmethod
    def inputs(*arrays: np.ndarray) -> tuple:
        """The caller's arrays, as the kernels take them (here: themselves)."""
        return arrays

    @staticmethod
    def output(field, x: np.ndarray) -> None:
        """The solution `field` into the caller's x (here: it is x)."""

    @staticmethod
    def fill(field, value: float) -> None:
        field[...] = value

    @staticmethod
    def scale(field, exponent: int) -> None:
        """field *= 2^exponent, exactly."""
        np.ldexp(field, exponent, out=field)


ON_PROCESSOR = OnProcessor()


@dataclass(frozen=True)
class PoissonResult:
    iterations: int
    residual: float  # ||b - A x|| / max(||b||, tiny) of the returned x [-]
    converged: bool
    mean_removed: float = 0.0  # singular case: the mean of b taken out (0 for a compatible b)


class Slabs:
    """The x planes [lo, hi) of one grid level that this MPI rank works on (bounds: the first
    plane of every rank and the end), or the whole level on one rank (comm None): where the
    planes beside the slab come from, and the gathers that make a sum or a field whole."""

    def __init__(self, shape, comm=None, bounds=None, periodic_x=False, kernels=poisson_kernels):
        nx, ny, nz = shape
        self.shape = shape
        self.comm = comm
        self.k = kernels  # column_words of its partial sums
        if comm is None:
            bounds = np.array([0, nx], dtype=np.int64)
        rank = 0 if comm is None else comm.Get_rank()
        self.lo, self.hi = int(bounds[rank]), int(bounds[rank + 1])
        self.bounds = bounds
        self.words = np.zeros(WORDS, dtype=np.int64)  # scratch of the exact sums
        # (plane to receive, its owner, tag) and (plane to send, to whom, tag) beside the slab;
        # tag 0: a slab's first plane, which is its left neighbour's right halo, 1: its last
        self.receive, self.send = [], []
        # the same two planes deep (first plane of the two, peer, tag 2: a slab's first two,
        # 3: its last two), where every slab has room for them (`wide`), and the planes a
        # colour is swept on with them: the slab and the plane either side (`extended`)
        self.wide_receive, self.wide_send = [], []
        self.wide = False
        self.extended = (self.lo, self.hi)
        self.persistent = {}  # (id(field), wide) -> (field, its persistent requests): `halo`
        self.counts = {}  # plane size -> (counts, displacements) of `gather`
        if comm is None:
            return
        from mpi4py import MPI

        self.mpi = MPI  # looked up once: the solver's messages number thousands a solve
        if self.lo == self.hi:
            return

        def owner(plane):
            return int(np.searchsorted(bounds, plane, side="right")) - 1

        left = self.lo - 1 if self.lo > 0 else (nx - 1 if periodic_x else None)
        right = self.hi if self.hi < nx else (0 if periodic_x else None)
        for plane, mine, tag in ((right, self.hi - 1, 0), (left, self.lo, 1)):
            if plane is not None and owner(plane) != rank:
                self.receive.append((plane, owner(plane), tag))
                self.send.append((mine, owner(plane), 1 - tag))
        self.wide = _two_deep(bounds, periodic_x)
        if self.wide:
            if right is not None:
                self.wide_receive.append((right, owner(right), 2))
                self.wide_send.append((self.hi - 2, owner(right), 3))
            if left is not None:
                self.wide_receive.append((left - 1, owner(left), 3))
                self.wide_send.append((self.lo, owner(left), 2))
            self.extended = (self.lo - (left is not None), self.hi + (right is not None))

    def __reduce__(self):
        return Slabs, (self.shape,)  # a copy sent to another process is whole until split there

    @property
    def split(self) -> bool:
        return self.comm is not None

    def halo(self, field: np.ndarray, wide: bool = False) -> None:
        """The planes beside the slab from the ranks that own them: one either side, or two
        with `wide` (where the slabs allow it: `wide`). The messages of each field
        are persistent requests, made at its first halo and started again at each: two calls
        into MPI a halo instead of one a message and a wait (the solver halos the same few
        arrays thousands of times a solve)."""
        receive, send = (self.wide_receive, self.wide_send) if wide else (self.receive, self.send)
        if not receive:
            return
        depth = 2 if wide else 1
        held = self.persistent.get((id(field), wide))
        if held is None or held[0] is not field:  # (the field is kept: its id stays its own)
            requests = [
                self.comm.Recv_init(field[plane : plane + depth], source=src, tag=tag)
                for plane, src, tag in receive
            ]
            requests += [
                self.comm.Send_init(field[plane : plane + depth], dest=dst, tag=tag)
                for plane, dst, tag in send
            ]
            held = self.persistent[(id(field), wide)] = (field, requests)
        self.mpi.Prequest.Startall(held[1])
        self.mpi.Request.Waitall(held[1])

    def sum(self, partial: np.ndarray) -> float:
        """The sum of every rank's column partial sums: each rank's columns summed exactly
        (kernels/exact_sum.py) and the words added over the ranks (an Allreduce of 69 int64),
        so the same double on any number of ranks."""
        ny = self.shape[1]
        self.k.column_words(partial, self.lo * ny, self.hi * ny, self.words)
        if self.comm is not None:
            self.comm.Allreduce(self.mpi.IN_PLACE, [self.words, self.mpi.INT64_T], op=self.mpi.SUM)
        return exact_value(self.words)

    def whole_sum(self, partial: np.ndarray) -> float:
        """The sum of every column partial sum of this rank's partial (a field kept whole on
        every rank), as `sum` makes it."""
        self.k.column_words(partial, 0, partial.shape[0], self.words)
        return exact_value(self.words)

    def total(self, count: int) -> int:
        """The sum of every rank's count."""
        return count if self.comm is None else int(self.comm.allreduce(count))

    def gather(self, field: np.ndarray) -> None:
        """Every rank's planes of a field (C-ordered, x first: cells or faces), into the field on
        every rank."""
        if self.comm is not None:
            plane = field[0].size
            counts = self.counts.get(plane)
            if counts is None:
                counts = self.counts[plane] = (np.diff(self.bounds) * plane, self.bounds[:-1] * plane)
            self.comm.Allgatherv(self.mpi.IN_PLACE, [field, *counts, self.mpi.DOUBLE])


class _Level:
    """One coarse level: its shape, the coarsening factors from the level above, coefficients,
    diagonal and work arrays."""

    def __init__(self, shape, factors, ih2, flags, on):
        self.shape = shape
        self.factors = factors
        self.ih2 = on.array(ih2)
        self.red_black = colourable(shape, flags)
        nx, ny, nz = shape
        self.c, self.diag, self.inv_diag, self.x, self.b, self.r, self.tmp = (
            on.zeros(shape) for _ in range(7)
        )
        self.ax, self.ay, self.az = (
            on.zeros((nx + 1, ny, nz)),
            on.zeros((nx, ny + 1, nz)),
            on.zeros((nx, ny, nz + 1)),
        )
        self.partial = on.zeros(nx * ny)
        self.slabs = Slabs(shape, kernels=on.kernels)


class Multigrid:
    """Geometric multigrid V-cycle z = M^-1 r for the preconditioned conjugate gradient: cells
    merged in pairs along every axis with an even count of at least 4, coefficients re-discretised
    (means of the fine ones), restriction by averaging and prolongation by injection (a multiple
    of its transpose), red-black Gauss-Seidel sweeps before the coarse correction and their
    adjoint (the colours in the other order) after, or the same damped Jacobi sweeps before and
    after on a level that cannot be coloured: M is symmetric positive definite, as CG needs."""

    def __init__(self, grid: FluidGrid, flags, on=ON_PROCESSOR):
        self.flags = flags  # periodic_x, periodic_y, dirichlet_bottom, dirichlet_top (uint8)
        self.on = on
        shape = tuple(grid.shape)
        ih2 = 1.0 / np.asarray(grid.spacing, dtype=np.float64) ** 2
        self.levels: list[_Level] = []
        while int(np.prod(shape)) > COARSEST_TARGET:
            factors = tuple(2 if n % 2 == 0 and n >= 4 else 1 for n in shape)
            if factors == (1, 1, 1):
                break
            shape = tuple(n // f for n, f in zip(shape, factors, strict=True))
            ih2 = ih2 / np.asarray(factors, dtype=np.float64) ** 2
            self.levels.append(_Level(shape, factors, ih2, flags, on))
        self.usable = int(np.prod(shape)) <= COARSEST_LIMIT and bool(self.levels)
        self.grid = grid
        fine = grid.shape
        self.fine_x, self.fine_tmp, self.fine_r = (on.zeros(fine) for _ in range(3))
        self.fine_partial = on.zeros(fine[0] * fine[1])
        self.fine_slabs = Slabs(fine, kernels=on.kernels)
        self.fine_red_black = colourable(fine, flags)

    @property
    def k(self):
        """The kernels of the place the fields are at (a property: a module is not pickled with a
        fluid sent to another rank)."""
        return self.on.kernels

    def update_spacing(self) -> None:
        """Take the grid's current spacing (a grid following the top wall changes it)."""
        ih2 = 1.0 / self.grid.spacing**2
        for level in self.levels:
            ih2 = ih2 / np.asarray(level.factors, dtype=np.float64) ** 2
            self.on.put(level.ih2, ih2)

    def describe(self) -> str:
        shapes = " -> ".join("x".join(str(n) for n in level.shape) for level in self.levels)
        return f"multigrid V-cycle ({len(self.levels) + 1} levels, coarsest {shapes.split(' -> ')[-1]})"

    def setup(self, c, ax, ay, az):
        """Coarse coefficients and diagonals from the fine ones (once per solve)."""
        px, py, db, dt = self.flags
        above = (c, ax, ay, az)
        for level in self.levels:
            fx, fy, fz = level.factors
            self.k.coarsen_coefficients(*above, fx, fy, fz, level.c, level.ax, level.ay, level.az)
            self.k.prepare_system(
                level.b, level.c, level.ax, level.ay, level.az, px, py, db, dt, 0.0, 0.0, level.ih2,
                level.b, level.diag, level.inv_diag, level.partial,
            )  # fmt: skip
            above = (level.c, level.ax, level.ay, level.az)

    def apply(self, r, z, fine):
        """z = M^-1 r; fine = (diag, inv_diag, ax, ay, az, ih2) of the fine operator."""
        self._cycle(-1, r, z, fine)

    def _smooth(self, rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, sweeps, slabs, zero=False, first=None):
        """`sweeps` sweeps of x: red-black Gauss-Seidel, colour `first` first, or damped Jacobi
        where `first` is None (zero: x is 0 everywhere, its planes beside the slab too, so the
        first sweep needs no messages)."""
        px, py = self.flags[0], self.flags[1]
        lo, hi = slabs.lo, slabs.hi
        if first is not None and self.on.fused and not slabs.split:  # a run of planes a thread
            runs = numba.get_num_threads()
            red_black_smooth(rhs, x, inv_diag, ax, ay, az, px, py, ih2, first, sweeps, runs)
            return
        if first is not None and slabs.wide:
            # one message a sweep instead of one a colour: with the two planes either side, the
            # first colour is swept on the plane either side too (the same inputs and operations
            # as their owners', so the same bits), which the second colour of the slab then reads
            # (the right-hand side of those planes: _cycle's halo)
            for sweep in range(sweeps):
                if sweep or not zero:
                    slabs.halo(x, wide=True)
                self.k.red_black_sweep(rhs, x, inv_diag, ax, ay, az, px, py, ih2, first, *slabs.extended)
                self.k.red_black_sweep(rhs, x, inv_diag, ax, ay, az, px, py, ih2, 1 - first, lo, hi)
            return
        if first is not None:  # each colour reads the other's planes beside the slab
            for half in range(2 * sweeps):
                if half or not zero:
                    slabs.halo(x)
                colour = first if half % 2 == 0 else 1 - first
                self.k.red_black_sweep(rhs, x, inv_diag, ax, ay, az, px, py, ih2, colour, lo, hi)
            return
        if not slabs.split:  # the pairs of sweeps in one call
            pairs = sweeps // 2
            self.k.jacobi_smooth_pairs(
                rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, SMOOTHING_WEIGHT, tmp, pairs
            )
            return
        for sweep in range(sweeps // 2):
            if sweep or not zero:
                slabs.halo(x)
            self.k.jacobi_smooth(
                rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, SMOOTHING_WEIGHT, tmp, lo, hi
            )
            slabs.halo(tmp)
            self.k.jacobi_smooth(
                rhs, tmp, inv_diag, diag, ax, ay, az, px, py, ih2, SMOOTHING_WEIGHT, x, lo, hi
            )

    def _cycle(self, index, rhs, x, fine):
        if index < 0:
            diag, inv_diag, ax, ay, az, ih2 = fine
            tmp, res, partial = self.fine_tmp, self.fine_r, self.fine_partial
            slabs = self.fine_slabs
            red_black = self.fine_red_black
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
            slabs = level.slabs
            red_black = level.red_black
        self.on.fill(x, 0.0)
        if index == len(self.levels) - 1:
            self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, COARSEST_SWEEPS, slabs, zero=True)
            return
        pre, post = (0, 1) if red_black else (None, None)
        if red_black and slabs.wide:  # the smoothing sweeps the plane either side too
            slabs.halo(rhs)
        self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, SWEEPS, slabs, zero=True, first=pre)
        px, py = self.flags[0], self.flags[1]
        slabs.halo(x)
        self.k.residual(rhs, x, diag, ax, ay, az, px, py, ih2, res, partial, slabs.lo, slabs.hi)
        coarse = self.levels[index + 1]
        if coarse.slabs.split or not slabs.split:
            self.k.restrict(res, *coarse.factors, coarse.b, coarse.slabs.lo, coarse.slabs.hi)
        else:  # the first level solved whole on every rank
            slabs.gather(res)
            self.k.restrict(res, *coarse.factors, coarse.b, 0, coarse.shape[0])
        self._cycle(index + 1, coarse.b, coarse.x, fine)
        self.k.prolong_add(coarse.x, *coarse.factors, x, slabs.lo, slabs.hi)
        self._smooth(rhs, x, tmp, diag, inv_diag, ax, ay, az, ih2, SWEEPS, slabs, first=post)


def _two_deep(bounds: np.ndarray, periodic_x: bool) -> bool:
    """Whether every rank's two planes either side of its slab (bounds: every rank's first plane
    and the end) lie in one neighbour's slab each, none its own nor both sides' at once: every
    slab two planes or more, and four or more beyond each slab where both sides wrap around. The
    same answer on every rank, so that all take the same messages."""
    sizes = np.diff(bounds)
    if sizes.size < 2 or np.any(sizes < 2):
        return False
    nx = int(bounds[-1])
    return not periodic_x or bool(np.all(nx - sizes >= 4))


def colourable(shape, flags) -> bool:
    """Whether red-black colouring of a level leaves no two neighbours of one colour: an even
    cell count along each periodic axis (flags: periodic_x, periodic_y, ...)."""
    return (not flags[0] or shape[0] % 2 == 0) and (not flags[1] or shape[1] % 2 == 0)


def preconditioner_for(grid: FluidGrid) -> str:
    """The conjugate gradient's preconditioner for a fluid's grid: the multigrid V-cycle from
    MULTIGRID_FROM cells (where the shape allows one), else the diagonal."""
    return "multigrid" if grid.cell_count >= MULTIGRID_FROM else "jacobi"


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
        split_cells: int = 4096,
        on=ON_PROCESSOR,
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
        self.boundaries = (bottom, top)
        self.method = method
        self.preconditioner = preconditioner
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.split_cells = int(split_cells)  # the least cells a rank of a level split across ranks
        self.on = on  # where the fields live
        self.periodic_x = np.uint8(bool(grid.periodic[0]))
        self.periodic_y = np.uint8(bool(grid.periodic[1]))
        self.dirichlet_bottom = np.uint8(bottom == "dirichlet")
        self.dirichlet_top = np.uint8(top == "dirichlet")
        self.ih2 = on.array(1.0 / np.asarray(grid.spacing, dtype=np.float64) ** 2)
        shape = tuple(grid.shape)
        self.rhs, self.diag, self.inv_diag, self.r, self.z, self.p, self.q = (
            on.zeros(shape) for _ in range(7)
        )
        columns = shape[0] * shape[1]
        self.part_a, self.part_b, self.part_c = (on.zeros(columns) for _ in range(3))
        self.multigrid = None
        if method == "pcg" and preconditioner == "multigrid":
            flags = (self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top)
            multigrid = Multigrid(grid, flags, on)
            self.multigrid = multigrid if multigrid.usable else None
        self.slabs = Slabs(shape, kernels=on.kernels)

    @classmethod
    def like(cls, solver: PoissonSolver, on) -> PoissonSolver:
        """A solver of this class with solver's grid, boundaries and settings, not split across
        ranks, its fields and kernels at `on` (physics/fluid/device_poisson.py: on a GPU)."""
        return cls(
            solver.grid, *solver.boundaries, solver.method, solver.tolerance, solver.max_iterations,
            solver.preconditioner, solver.split_cells, on,
        )  # fmt: skip

    def split(self, comm) -> None:
        """From now on solve on slabs of x planes, one per rank of the MPI communicator comm (one
        of the solves' own: their messages carry no other tag), every rank calling solve() with
        the same arguments at the same time (a collective); a second call with the same comm
        changes nothing. The slabs' planes are multiples of the largest power of two that leaves
        every rank one at least and the busiest at most SLAB_IMBALANCE times an even share, so
        that the multigrid levels coarsened along x down to it are split alike. A level that
        would give a rank fewer than split_cells cells, the coarsest and the coarser ones are
        solved whole on every rank; so are the Jacobi method, a grid too small and one rank."""
        size = comm.Get_size()
        small = self.grid.cell_count < self.split_cells * size
        if self.method != "pcg" or size == 1 or small or self.slabs.comm is comm:
            return
        nx = self.grid.shape[0]
        levels = self.multigrid.levels if self.multigrid is not None else []
        factor = [1]  # the fine planes per plane of each coarse level
        for level in levels:
            factor.append(factor[-1] * level.factors[0])
        even = -(-nx // size)
        block = max(
            (f for f in factor if nx // f >= size and f * -(-(nx // f) // size) <= SLAB_IMBALANCE * even),
            default=1,
        )
        bounds = block * (np.arange(size + 1, dtype=np.int64) * (nx // block) // size)
        periodic = bool(self.periodic_x)
        self.slabs = Slabs(self.grid.shape, comm, bounds, periodic)
        if self.multigrid is not None:
            self.multigrid.fine_slabs = self.slabs
            for level, f in zip(levels, factor[1:], strict=True):
                small = int(np.prod(level.shape)) < self.split_cells * size
                # the coarsest's 40 sweeps would cost more in messages than the work they share
                whole = f > block or small or level is levels[-1]
                level.slabs = Slabs(level.shape) if whole else Slabs(level.shape, comm, bounds // f, periodic)

    @property
    def k(self):
        """The kernels of the place the fields are at (a property: a module is not pickled with a
        fluid sent to another rank)."""
        return self.on.kernels

    def update_spacing(self) -> None:
        """Take the grid's current spacing: call after grid.set_height (a grid that follows the
        top wall); the coefficients are rebuilt by every solve."""
        self.on.put(self.ih2, 1.0 / self.grid.spacing**2)
        if self.multigrid is not None:
            self.multigrid.update_spacing()

    def describe(self) -> str:
        if self.method == "jacobi":
            name = "Jacobi iteration"
        elif self.multigrid is not None:
            name = f"conjugate gradient preconditioned with a {self.multigrid.describe()}"
        else:
            name = "conjugate gradient, Jacobi-preconditioned"
        return f"{name}, tolerance {self.tolerance:g}{self.on.where}"

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
        singular = not (self.dirichlet_bottom or self.dirichlet_top) and not c.any()
        on = self.on
        field, b, c, ax, ay, az = on.inputs(x, b, c, ax, ay, az)  # field: x where the kernels work
        self.k.prepare_system(
            b, c, ax, ay, az, self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top,
            float(bottom_value), float(top_value), self.ih2, self.rhs, self.diag, self.inv_diag, self.part_a,
        )  # fmt: skip
        mean_removed = 0.0
        nx = self.grid.shape[0]
        if singular:  # the right-hand side stays whole on every rank
            self.k.column_sums(self.rhs, self.part_c, 0, nx)
            mean_removed = self.slabs.whole_sum(self.part_c) / self.rhs.size
            self.k.shift(self.rhs, mean_removed, 0, nx)
            self.k.column_squares(self.rhs, self.part_a, 0, nx)
        rhs_norm = math.sqrt(self.slabs.whole_sum(self.part_a))
        if rhs_norm == 0.0 and not on.host(self.rhs).any():
            on.fill(field, 0.0)
            on.output(field, x)
            return PoissonResult(0, 0.0, True, mean_removed)
        # a right-hand side far from unit size (an incremental pressure that has settled decays
        # towards 1e-300) is scaled by a power of two, exactly, taken from its largest value, so
        # that the iteration's sums of squares neither underflow nor overflow
        rescale = not (2.0**-RESCALE_EXPONENT <= rhs_norm <= 2.0**RESCALE_EXPONENT)
        if rescale:
            exponent = math.frexp(float(np.abs(on.host(self.rhs)).max()))[1]
            on.scale(self.rhs, -exponent)
            on.scale(field, -exponent)
            self.k.column_squares(self.rhs, self.part_a, 0, nx)
            rhs_norm = math.sqrt(self.slabs.whole_sum(self.part_a))
        scale = 1.0 / max(rhs_norm, TINY)
        if self.method == "pcg":
            iterations, res = self._pcg(field, c, ax, ay, az, singular, scale)
        else:
            iterations, res = self._jacobi(field, ax, ay, az, scale)
        if singular:
            self.k.shift(field, self._mean(field), self.slabs.lo, self.slabs.hi)
        self.slabs.gather(field)
        if rescale:
            on.scale(field, exponent)
        on.output(field, x)
        return PoissonResult(iterations, res, res <= self.tolerance, mean_removed)

    def explicit_step(self, x, b, c, ax, ay, az, bottom_value: float = 0.0, top_value: float = 0.0) -> None:
        """One forward-Euler step of the system that solve() would take one backward-Euler step
        of: with A = c + (the face and boundary terms), c (x' - x) = b - A x, so x += (b - A x)/c
        in place (c > 0 everywhere; no cell may have been eliminated into c)."""
        field, b_, c_, ax, ay, az = self.on.inputs(x, b, c, ax, ay, az)
        self.k.prepare_system(
            b_, c_, ax, ay, az, self.periodic_x, self.periodic_y, self.dirichlet_bottom, self.dirichlet_top,
            float(bottom_value), float(top_value), self.ih2, self.rhs, self.diag, self.inv_diag, self.part_a,
        )  # fmt: skip
        self.k.residual(
            self.rhs, field, self.diag, ax, ay, az, self.periodic_x, self.periodic_y, self.ih2,
            self.r, self.part_a, 0, self.grid.shape[0],
        )  # fmt: skip
        r = self.on.host(self.r)
        np.divide(r, self.on.host(c_), out=r)
        values = self.on.host(field)  # x itself on the processor
        values += r
        self.on.put(field, values)
        self.on.output(field, x)

    # -- helpers -----------------------------------------------------------------------------

    def _mean(self, field: np.ndarray) -> float:
        self.k.column_sums(field, self.part_c, self.slabs.lo, self.slabs.hi)
        return self.slabs.sum(self.part_c) / field.size

    def _true_residual(self, x, ax, ay, az) -> float:
        self.slabs.halo(x)
        self.k.residual(
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
            self.slabs.lo,
            self.slabs.hi,
        )
        return math.sqrt(self.slabs.sum(self.part_a))

    def _pcg(self, x, c, ax, ay, az, singular, scale):
        n = x.size
        slabs = self.slabs
        lo, hi = slabs.lo, slabs.hi
        iterations = 0
        res = self._true_residual(x, ax, ay, az) * scale
        fine = (self.diag, self.inv_diag, ax, ay, az, self.ih2)
        if self.multigrid is not None:
            self.multigrid.setup(c, ax, ay, az)
        compiled = self.multigrid is None and not slabs.split and self.on.fused  # the inner loop in one call
        # restarted from the true residual if the recursively updated one drifted from it
        while res > self.tolerance and iterations < self.max_iterations:
            self.k.precondition(self.r, self.inv_diag, self.z, self.part_b, self.part_c, lo, hi)
            self._multigrid(fine)
            rz = slabs.sum(self.part_b)
            z_mean = slabs.sum(self.part_c) / n if singular else 0.0
            self.k.new_direction(self.p, self.z, 0.0, z_mean, lo, hi)
            if compiled:
                inner = diagonal_cg_serial if use_serial() else diagonal_cg
                iterations, status = inner(
                    x, self.r, self.p, self.q, self.z, self.diag, self.inv_diag, ax, ay, az,
                    self.periodic_x, self.periodic_y, self.ih2, self.part_a, self.part_b, self.part_c,
                    slabs.words, rz, singular, scale, self.tolerance, iterations, self.max_iterations,
                )  # fmt: skip
                if status == 2:
                    return iterations, self._true_residual(x, ax, ay, az) * scale
                res = self._true_residual(x, ax, ay, az) * scale
                continue
            while iterations < self.max_iterations:
                slabs.halo(self.p)
                self.k.apply_operator(
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
                    lo,
                    hi,
                )
                pq = slabs.sum(self.part_a)
                if not pq > 0.0:
                    return iterations, self._true_residual(x, ax, ay, az) * scale
                alpha = rz / pq
                self.k.cg_step(
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
                    lo,
                    hi,
                )
                iterations += 1
                if math.sqrt(slabs.sum(self.part_a)) * scale <= self.tolerance:
                    break
                self._multigrid(fine)
                rz_new = slabs.sum(self.part_b)
                z_mean = slabs.sum(self.part_c) / n if singular else 0.0
                self.k.new_direction(self.p, self.z, rz_new / rz, z_mean, lo, hi)
                rz = rz_new
            res = self._true_residual(x, ax, ay, az) * scale
        return iterations, res

    def _multigrid(self, fine) -> None:
        """Replace the diagonal preconditioner's z (and its partial sums) by the V-cycle's."""
        if self.multigrid is not None:
            self.multigrid.apply(self.r, self.z, fine)
            self.k.column_dots(self.r, self.z, self.part_b, self.part_c, self.slabs.lo, self.slabs.hi)

    def _jacobi(self, x, ax, ay, az, scale):
        src, dst = x, self.r
        iterations = 0
        while True:
            self.k.jacobi_sweep(
                self.rhs, src, self.diag, self.inv_diag, ax, ay, az,
                self.periodic_x, self.periodic_y, self.ih2, dst, self.part_a,
            )  # fmt: skip
            res = math.sqrt(self.slabs.whole_sum(self.part_a)) * scale  # of src
            if res <= self.tolerance or iterations >= self.max_iterations:
                break
            iterations += 1
            src, dst = dst, src
        if src is not x:
            self.on.put(x, src)
        return iterations, res
