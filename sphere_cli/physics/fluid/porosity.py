"""Porosity of the fluid cells, and the per-cell mean particle velocity and diameter, from the
particles (kernels/fluid/porosity.py has the method: exact lens volumes of each particle with a
cell-centred sampling sphere of radius half the smallest cell edge).

    porosity = Porosity(grid, particles.count)      # once, when the scene is built
    porosity.measure(particles, phi)                 # each fluid step: fills phi (nx, ny, nz)
    porosity.measure(particles, phi, vbar, dbar)     # also the means (nx, ny, nz, 3) and (nx, ny, nz)
    porosity.cell_of                                 # (N,) flat cell of each particle centre, as
                                                     # of the last measure ((i*ny + j)*nz + k);
                                                     # given n < N particles (a Darcy rank's
                                                     # window), only the first n entries, theirs

phi is clamped to [0, 1]: below 0 only where overlapping particles put more solid in a sampling
sphere than it holds; the first clamp is logged as a warning, and measure() returns the number
of cells clamped. The rate dphi/dt is the backward difference (phi - phi_previous) / dt_fluid,
which each model takes over its own fluid step; on a grid that moved since, also against
measure_earlier's (the grains a fluid step back, on the cells now). No array is allocated
after construction except the counting sort's small cursor array.
"""

from __future__ import annotations

import logging
import types

import numpy as np

from ...kernels.fluid.porosity import bin_particles, bin_particles_serial, sample_cells
from ...kernels.neighbors import counting_sort
from ...kernels.serial import use_serial
from .grid import FluidGrid
from .poisson import Slabs

log = logging.getLogger("sphere.fluid.porosity")


class Porosity:
    def __init__(self, grid: FluidGrid, count: int):
        self.grid = grid
        self.origin = np.asarray(grid.origin, dtype=np.float64)
        self.spacing = np.asarray(grid.spacing, dtype=np.float64)
        self.shape = np.asarray(grid.shape, dtype=np.int64)
        self.periodic = np.asarray(grid.periodic, dtype=np.uint8)
        self.cell_of = np.zeros(count, dtype=np.int64)
        self.wrapped = np.zeros((count, 3))
        self.cell_start = np.zeros(grid.cell_count + 1, dtype=np.int64)
        self.order = np.zeros(count, dtype=np.int64)
        self.reach = np.zeros(3, dtype=np.int64)
        self.subdivisions = sampling_parts(grid)
        # the farthest a sampling sphere's centre lies from its cell's, as a fraction of the edge
        self.part_offset = (self.subdivisions - 1) / (2.0 * self.subdivisions)
        self._reach = np.zeros(3)
        self._no_velocity = np.zeros((1, 1, 1, 3))
        self._no_diameter = np.zeros((1, 1, 1))
        self._spare: dict[str, np.ndarray] = {}
        self.clamped_cells = 0
        self._warned = False
        self._warned_parts = False
        self.gpu_sort = None  # on a GPU: its counts, starts, next places, order and clamped count
        # split across MPI ranks: the slabs of x planes whose cells this rank samples (the fluid's
        # pressure solve's, set by its split_grid), the rest gathered from the other ranks
        self.slabs = Slabs(grid.shape)

    @property
    def sampling_radius(self) -> float:
        """[m], of the grid's current cells (a grid following the top wall changes them)."""
        return self.grid.sampling_radius

    def measure(self, particles, porosity, mean_velocity=None, mean_diameter=None, largest=None) -> int:
        """Fill porosity (nx, ny, nz) [-] from particles.pos/.radius; with mean_velocity
        (nx, ny, nz, 3) [m/s] and/or mean_diameter (nx, ny, nz) [m] also the lens-volume-weighted
        means over the particles reaching each sampling sphere (0 where none does). Returns the
        number of cells whose porosity was clamped at 0."""
        pos, radius = particles.pos, particles.radius
        # (a rank of a split run may pass fewer particles than the scene's: those its cells reach)
        n = pos.shape[0]
        cell_of, wrapped, order = self.cell_of[:n], self.wrapped[:n], self.order[:n]
        bin_in_cells(pos, self.origin, self.spacing, self.shape, self.periodic, cell_of, wrapped)
        counting_sort(cell_of, self.cell_start.size - 1, self.cell_start, order)
        want, vbar, dbar, largest = self._sampled(radius, mean_velocity, mean_diameter, largest)
        plane = int(self.shape[1] * self.shape[2])
        slabs = self.slabs
        clamped = sample_cells(
            wrapped, particles.vel, radius, self.origin, self.spacing, self.shape, self.periodic,
            self.sampling_radius, self.subdivisions, largest, self.reach, self.cell_start, order, want,
            porosity, vbar, dbar,
            slabs.lo * plane, slabs.hi * plane,
        )  # fmt: skip
        if slabs.split:
            for field in (porosity, vbar, dbar) if want else (porosity,):
                slabs.gather(field)
            clamped = slabs.total(int(clamped))
        return self.report_clamped(int(clamped))

    def measure_earlier(self, particles, dt: float, porosity, largest=None, mean_velocity=None) -> int:
        """`measure` of the particles dt [s] earlier, taken back along their velocities now, on
        the grid's cells now: (phi - this)/dt is the rate at points fixed in space, which a grid
        that moved since its last measure cannot take from two measures of its cells (the lens
        estimate of cells that slid past grains at rest changes). Exact for grains at rest or
        in uniform motion, first order in dt otherwise. With mean_velocity, also the grains'
        mean velocity per cell. Call it before `measure`, whose bins (cell_of) the drag reads."""
        pos, vel = particles.pos, particles.vel
        back = self._spare.get("earlier")
        if back is None or back.shape[0] < pos.shape[0]:
            back = self._spare["earlier"] = np.zeros_like(pos)
        back = back[: pos.shape[0]]
        np.multiply(vel, -dt, out=back)
        back += pos
        earlier = types.SimpleNamespace(pos=back, vel=vel, radius=particles.radius)
        return self.measure(earlier, porosity, mean_velocity, largest=largest)

    def _sampled(self, radius, mean_velocity, mean_diameter, largest=None) -> tuple:
        """The reach of the sampling spheres into the bins, now (largest: the largest radius of
        all the particles, given where only some are passed); (whether means are wanted, and the
        arrays for them, given or scratch, and the largest radius)."""
        # bins on either side of a cell that a particle touching its sampling sphere can lie in
        if largest is None:
            largest = float(radius.max()) if radius.size else 0.0
        np.floor(0.5 + self.part_offset + (self.sampling_radius + largest) / self.spacing, out=self._reach)
        self.reach[:] = self._reach
        want = mean_velocity is not None or mean_diameter is not None
        vbar, dbar = mean_velocity, mean_diameter
        if vbar is None:
            vbar = self._scratch("velocity", tuple(self.grid.shape) + (3,)) if want else self._no_velocity
        if dbar is None:
            dbar = self._scratch("diameter", tuple(self.grid.shape)) if want else self._no_diameter
        return want, vbar, dbar, largest

    def gpu_measure(self, particles, porosity, mean_velocity=None, mean_diameter=None) -> tuple:
        """`measure` on a GPU (kernels/fluid/cuda_porosity.py), for a grid that keeps its cells:
        (the launches, the (1,) count of clamped cells they write, for report_clamped, and the
        sort's own arrays, which the launches write before they read them: GpuSteps.scratch)."""
        from ...kernels.fluid import cuda_porosity as k

        p, n, cells = particles, particles.count, self.grid.cell_count
        if self.gpu_sort is None:
            self.gpu_sort = tuple(np.zeros(size, np.int32) for size in (cells, cells + 1, cells, n, 1))
        count, start, following, order, clamped = self.gpu_sort
        want, vbar, dbar, largest = self._sampled(p.radius, mean_velocity, mean_diameter)
        grid = (self.origin, self.spacing, self.shape, self.periodic)
        sample = (
            self.wrapped, p.vel, p.radius, *grid, self.sampling_radius, self.subdivisions, largest,
            self.reach, start, order, want, porosity, vbar, dbar, clamped,
        )  # fmt: skip
        binned = (p.pos, *grid, self.cell_of, self.wrapped)
        return (
            [
                (k.bin_in_fluid_cells, n, (*binned, count, clamped)),
                (k.cell_starts, cells, (count, start, following)),
                (k.fill_cells, n, (self.cell_of, following, order)),
                (k.sort_cells, cells, (start, order, count)),
                (k.sample_cells, cells, sample),
            ],
            clamped,
            (*self.gpu_sort, self.cell_of, self.wrapped),
        )

    def split(self, comm, solved) -> None:
        """Sample on slabs of x planes, one per rank of the MPI communicator comm: those of the
        pressure solve (`solved`, a Slabs) where it is split, else the planes shared out
        evenly (a grid too small for its solve to be split may hold many particles: each rank
        then still takes only those its cells reach). Again with the same comm: nothing."""
        if solved.split:
            self.slabs = solved
        elif self.slabs.comm is not comm:
            nx, size = int(self.shape[0]), comm.Get_size()
            bounds = (np.arange(size + 1) * nx) // size
            self.slabs = Slabs(tuple(int(n) for n in self.shape), comm, bounds)

    def needed_by(self, pos: np.ndarray, largest: float) -> np.ndarray:
        """(ranks, n) bool: which ranks of a split run sample cells that can reach each of these
        particles (pos (n, 3) [m]): those whose slab of x planes, widened by the reach of the
        largest sampling sphere the grid can have (half its smaller x or y edge: the z edge of
        a grid following the top wall changes) from its part farthest along x (sampling_parts),
        holds the particle's bin. Whole bins are taken,
        so a rank gets every particle of each bin its cells visit."""
        bins = np.empty(pos.shape[0], dtype=np.int64)
        bin_in_cells(pos, self.origin, self.spacing, self.shape, self.periodic, bins, np.empty_like(pos))
        nx = int(self.shape[0])
        x = bins // int(self.shape[1] * self.shape[2])
        radius = 0.5 * min(self.spacing[0], self.spacing[1])
        reach = int(np.floor(0.5 + self.part_offset[0] + (radius + largest) / self.spacing[0]))
        bounds = self.slabs.bounds
        marks = np.zeros((bounds.size - 1, pos.shape[0]), dtype=bool)
        for rank, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
            if lo == hi:
                continue
            first, last = lo - reach, hi - 1 + reach  # the planes its cells visit, unwrapped
            if not self.periodic[0]:
                marks[rank] = (x >= first) & (x <= last)
            elif last - first + 1 >= nx:
                marks[rank] = True
            else:
                marks[rank] = (x - first) % nx <= last - first
        return marks

    def report_clamped(self, clamped: int) -> int:
        """Keep and (once) log the count of cells whose porosity was clamped at 0; returns it."""
        self.clamped_cells = clamped
        if clamped and not self._warned:
            self._warned = True
            log.warning(
                "porosity below 0 (overlapping particles fill a sampling sphere) clamped to 0 in %d of %d "
                "fluid cells; further clamps are not logged",
                clamped,
                self.grid.cell_count,
            )
        return self.clamped_cells

    def warn_if_outgrown(self, step: int) -> None:
        """Once a run, where a grid following the top wall has stretched its cells so far that
        they would now be sampled in another count of parts than the one kept from the case's
        cells (sampling_parts): too few spheres leave grains no cell counts, which can make the
        coupling unstable (user guide, "How the porosity is measured")."""
        if self._warned_parts:
            return
        now = sampling_parts(self.grid)
        if np.array_equal(now, self.subdivisions):
            return
        self._warned_parts = True
        log.warning(
            "step %d: the fluid cells, following the top wall, are now %s m; they would be sampled in "
            "%s parts, and the porosity keeps the %s counted from the case's cells (a count that "
            "changed would make it jump). Elongated cells sampled in too few spheres leave grains no "
            "cell counts, which can make the coupling unstable: start from cells about as tall as "
            "they will be",
            step, " x ".join(f"{x:.4g}" for x in self.spacing), " x ".join(str(n) for n in now),
            " x ".join(str(n) for n in self.subdivisions),
        )  # fmt: skip

    def _scratch(self, name: str, shape: tuple) -> np.ndarray:
        """A full-size array for the mean the caller did not ask for (made on first need)."""
        array = self._spare.get(name)
        if array is None:
            array = self._spare[name] = np.zeros(shape)
        return array


def sampling_parts(grid: FluidGrid) -> np.ndarray:
    """(3,) int64: the parts each cell is sampled in along each axis, its edge over the sampling
    sphere's diameter (the smallest edge) rounded: 1 x 1 x 1 for a cubic cell, 1 x 1 x 3 for a
    cell 2.64 times as tall as wide. One sphere in an elongated cell sees only its middle, and
    grains between two cells' spheres that neither counts move without changing any porosity (a
    bed at rest under such cells coupled to Navier-Stokes oscillated with growing amplitude).
    Taken from the grid as the case gives it, and kept: a grid following the top wall stretches
    its parts with its cells (a count that changed would make the porosity jump)."""
    ratio = np.asarray(grid.spacing, dtype=np.float64) / (2.0 * grid.sampling_radius)
    return np.maximum(np.floor(ratio + 0.5), 1.0).astype(np.int64)


def bin_in_cells(pos, origin, spacing, shape, periodic, cell_of, wrapped) -> None:
    """kernels/fluid/porosity.py bin_particles, or on one thread its serial twin
    (kernels/serial.py): the same cells, without a parallel region."""
    kernel = bin_particles_serial if use_serial() else bin_particles
    kernel(pos, origin, spacing, shape, periodic, cell_of, wrapped)


def particle_cells(grid: FluidGrid, pos: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out (N,) int64: the flat cell index (i*ny + j)*nz + k of each particle centre (periodic
    axes wrapped, others clamped to the grid); the same cells Porosity.cell_of holds."""
    bin_in_cells(
        pos,
        np.asarray(grid.origin, dtype=np.float64),
        np.asarray(grid.spacing, dtype=np.float64),
        np.asarray(grid.shape, dtype=np.int64),
        np.asarray(grid.periodic, dtype=np.uint8),
        out,
        np.empty_like(pos),
    )
    return out
