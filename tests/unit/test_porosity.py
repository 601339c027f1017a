"""Porosity of the fluid cells from the particles (physics/fluid/porosity.py, kernels/fluid/porosity.py):
exact lens volumes with a cell-centred sampling sphere of radius R = half the smallest cell edge
("Porosity estimation" in the documentation of the original sphere), stacked along the long
axes of an elongated cell."""

from __future__ import annotations

import ast
import itertools
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from sphere_cli.kernels.fluid.porosity import lens_volume
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.poisson import Slabs
from sphere_cli.physics.fluid.porosity import Porosity, particle_cells, sampling_parts

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def one_thread():
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(previous)


def make_grid(shape, edge, periodic=(True, True, False), origin=(0.0, 0.0, 0.0)):
    return FluidGrid(
        np.asarray(origin, dtype=float),
        np.asarray(edge, dtype=float) * np.ones(3),
        tuple(shape),
        np.asarray(periodic),
    )


def particles(pos, radius, vel=None):
    pos = np.atleast_2d(np.asarray(pos, dtype=float))
    vel = np.zeros_like(pos) if vel is None else np.atleast_2d(np.asarray(vel, dtype=float))
    return SimpleNamespace(
        pos=pos, vel=vel, radius=np.broadcast_to(np.asarray(radius, dtype=float), len(pos)).copy()
    )


def sphere_volume(r):
    return 4.0 / 3.0 * math.pi * r**3


def lens_by_quadrature(big_r, r, d, n=200_000):
    """Common volume as the integral along the line of centres of the area of the smaller of
    the two cross-section disks (midpoint rule; the integrand is continuous)."""
    lo, hi = max(-big_r, d - r), min(big_r, d + r)
    if hi <= lo:
        return 0.0
    x = lo + (np.arange(n) + 0.5) * (hi - lo) / n
    area = np.pi * np.minimum(big_r**2 - x**2, r**2 - (x - d) ** 2)
    return float(np.sum(np.clip(area, 0.0, None)) * (hi - lo) / n)


def test_lens_volume_limits_and_quadrature():
    R, r = 1.0, 0.6
    assert lens_volume(R, r, R + r) == 0.0 and lens_volume(R, r, 5.0) == 0.0
    # the lens formula meets both limits continuously
    assert lens_volume(R, r, R + r - 1e-9) == pytest.approx(0.0, abs=1e-15)
    assert lens_volume(R, r, R - r + 1e-12) == pytest.approx(sphere_volume(r), rel=1e-9)
    # full containment either way: the smaller sphere
    assert lens_volume(R, r, 0.0) == sphere_volume(r) and lens_volume(R, r, 0.3) == sphere_volume(r)
    assert lens_volume(r, R, 0.3) == sphere_volume(r)
    assert lens_volume(R, R, 0.0) == sphere_volume(R)
    for big, small, d in [
        (1.0, 0.6, 0.5),
        (1.0, 0.6, 1.2),
        (0.6, 1.0, 0.9),
        (1.0, 1.0, 1.0),
        (0.5, 0.05, 0.52),
    ]:
        exact = lens_by_quadrature(big, small, d)
        assert lens_volume(big, small, d) == pytest.approx(exact, rel=1e-7)  # midpoint error ~ 1/n^2
        assert lens_volume(big, small, d) == pytest.approx(lens_volume(small, big, d), rel=1e-12)


def test_single_particle_mean_velocity_and_diameter():
    grid = make_grid((4, 4, 4), 0.01)
    centre = [0.015, 0.015, 0.015]
    p = particles([centre, [0.0165, 0.015, 0.0145]], [0.002, 0.001], vel=[[1.0, 0.0, -2.0], [0.0, 3.0, 0.0]])
    phi = np.zeros(grid.shape)
    vbar = np.zeros(grid.shape + (3,))
    dbar = np.zeros(grid.shape)
    por = Porosity(grid, 2)
    assert por.measure(p, phi, vbar, dbar) == 0
    v1, v2 = sphere_volume(0.002), sphere_volume(0.001)  # both wholly inside cell (1,1,1)'s sphere
    assert phi[1, 1, 1] == pytest.approx(1.0 - (v1 + v2) / sphere_volume(0.005), rel=1e-14)
    assert vbar[1, 1, 1] == pytest.approx(
        [v1 / (v1 + v2), 3 * v2 / (v1 + v2), -2 * v1 / (v1 + v2)], rel=1e-14
    )
    assert dbar[1, 1, 1] == pytest.approx((0.004 * v1 + 0.002 * v2) / (v1 + v2), rel=1e-14)
    untouched = np.ones(grid.shape, dtype=bool)
    untouched[1, 1, 1] = False
    assert (phi[untouched] == 1.0).all() and not vbar[untouched].any() and not dbar[untouched].any()
    assert por.cell_of.tolist() == [(1 * 4 + 1) * 4 + 1] * 2
    out = np.zeros(2, dtype=np.int64)
    assert particle_cells(grid, p.pos, out).tolist() == por.cell_of.tolist()


def test_porosity_is_continuous_as_a_particle_crosses_cells():
    """A particle moved in steps of delta along a path through several cells, across cell
    faces and across the periodic face: no cell's phi may change by more than the Lipschitz
    bound of the lens volume, |dV/dd| = pi a^2 <= pi min(R, r)^2 (a: radius of the circle where
    the two sphere surfaces meet), so |delta phi| <= pi min(R, r)^2 delta / V_c. A particle
    missed or double-counted at any position would jump by a finite amount."""
    edge = 0.01
    grid = make_grid((3, 3, 4), edge)
    R, r = grid.sampling_radius, 0.003
    length = 0.03
    start = np.array([0.02, 0.024, 0.009])  # crosses the periodic faces x = 30 mm and y = 30 mm
    direction = np.array([1.0, 0.37, 0.5])
    direction /= np.linalg.norm(direction)
    delta = 2e-5
    por = Porosity(grid, 1)
    phi = np.zeros(grid.shape)
    previous = None
    bound = math.pi * min(R, r) ** 2 * delta / sphere_volume(R)
    worst = 0.0
    for step in range(1500):  # 30 mm along the path: about three cells in x, one in y and z
        pos = start + step * delta * direction
        pos[:2] %= length
        por.measure(particles(pos, r), phi)
        if previous is not None:
            worst = max(worst, np.abs(phi - previous).max())
        previous = phi.copy()
    assert 0.0 < worst <= bound * (1.0 + 1e-9), (worst, bound)


def test_periodic_images():
    """A configuration translated by one cell along a periodic axis gives the rolled porosity
    (particles near the periodic faces reach the cells on the other side through their
    images); a periodic axis of one cell equals the same column doubled into two cells."""
    rng = np.random.default_rng(4)
    grid = make_grid((4, 3, 3), 0.01)
    pos = rng.uniform(0.0, 1.0, (60, 3)) * [0.04, 0.03, 0.03]
    radius = rng.uniform(0.001, 0.004, 60)
    phi, moved = np.zeros(grid.shape), np.zeros(grid.shape)
    por = Porosity(grid, 60)
    por.measure(particles(pos, radius), phi)
    shifted = pos + [0.01, 0.0, 0.0]
    shifted[:, 0] %= 0.04
    por.measure(particles(shifted, radius), moved)
    assert np.allclose(moved, np.roll(phi, 1, axis=0), rtol=0, atol=1e-12)
    assert phi.min() < 0.9  # the scene does put solid in the cells

    column = make_grid((1, 1, 3), 0.01, periodic=(True, True, False))
    doubled = make_grid((2, 1, 3), 0.01, periodic=(True, True, False))
    pos1 = rng.uniform(0.0, 1.0, (8, 3)) * [0.01, 0.01, 0.03]
    rad1 = rng.uniform(0.001, 0.005, 8)
    one, two = np.zeros(column.shape), np.zeros(doubled.shape)
    Porosity(column, 8).measure(particles(pos1, rad1), one)
    pos2 = np.vstack([pos1, pos1 + [0.01, 0.0, 0.0]])
    Porosity(doubled, 16).measure(particles(pos2, np.concatenate([rad1, rad1])), two)
    assert np.allclose(two[0], one[0], rtol=0, atol=1e-12) and np.allclose(two[1], one[0], rtol=0, atol=1e-12)


def form_factor(k, rho):
    """Fourier transform of the indicator of a ball of radius rho [m^3]."""
    return 4.0 * np.pi * (np.sin(k * rho) - k * rho * np.cos(k * rho)) / k**3


def aliasing_bound(a, m, big_r, r, n=40):
    """Bound on |sampled solid fraction - s| for a simple cubic lattice (spacing a) of spheres
    of radius r, sampled by a sphere of radius R, averaged over m^3 lattice offsets uniformly
    spaced in one lattice cell. By Poisson summation the sampled solid volume is
    (1/a^3) sum_G F_R(G) F_r(G) exp(i G.c) over the reciprocal lattice; G = 0 gives exactly
    V_c s (the identity: averaged over all lattice offsets the sampled fraction IS the lattice
    fraction), and the m-point offset average keeps only G in m times the reciprocal lattice.
    Terms up to |n| = 40 are summed; the rest is below 1e-9 here (|F_R F_r| <= (4 pi)^2 R^2 r^2
    / k^4 (1 + 1/(k r))^2)."""
    ns = np.arange(-n, n + 1)
    grid = np.sqrt(sum(v**2 for v in np.meshgrid(ns, ns, ns, indexing="ij"))).ravel()
    k = 2.0 * np.pi * m / a * grid[grid > 0]
    return float(np.sum(np.abs(form_factor(k, big_r) * form_factor(k, r))) / (a**3 * sphere_volume(big_r)))


def test_simple_cubic_lattice_gives_its_solid_fraction():
    """Simple cubic lattice, spacing a = 1 mm, r = 0.4 mm: s = 4/3 pi r^3 / a^3 = 0.26808.
    Cells of 3 mm (R = 1.5 mm), periodic in x and y, walls in z; the interior cells (not
    touching the top and bottom) are compared. A single placement of the lattice differs from s
    by the lattice's granularity at the sphere's surface, within the Poisson-summation bound
    (0.046 for m = 1; observed 0.018); averaged over 4^3 offsets of the lattice the difference
    must fall below the m = 4 bound (1.4e-4)."""
    a, r = 1e-3, 0.4e-3
    s = sphere_volume(r) / a**3
    grid = make_grid((4, 4, 4), 3e-3)
    sites = np.arange(12) * a
    base = np.array(list(itertools.product(sites, sites, sites)))
    por = Porosity(grid, len(base))
    phi = np.zeros(grid.shape)
    for m in (1, 4):
        solid = []
        for offset in itertools.product(*[(np.arange(m) + 0.5) / m * a] * 3):
            por.measure(particles(base + offset, r), phi)
            solid.append(1.0 - phi[:, :, 1:3])
        solid = np.array(solid)
        bound = aliasing_bound(a, m, grid.sampling_radius, r)
        assert np.abs(solid.mean(axis=0) - s).max() <= bound, (m, np.abs(solid.mean(axis=0) - s).max(), bound)
    assert bound < 2e-4


def test_an_elongated_cell_is_sampled_along_its_length():
    """A cell 2.67 times as tall as wide is sampled in three spheres of half its width, stacked
    along its height (physics/fluid/porosity.py sampling_parts): a grain in its lower third,
    which one sphere at the cell's centre (2.67 mm away, beyond R + r = 2.5 mm) did not see,
    counts once in a third of the sampled volume. A cubic cell keeps its one sphere."""
    tall = FluidGrid(np.zeros(3), np.array([3e-3, 3e-3, 8e-3]), (2, 2, 2), np.array([True, True, False]))
    assert sampling_parts(tall).tolist() == [1, 1, 3]
    assert sampling_parts(make_grid((2, 2, 2), 3e-3)).tolist() == [1, 1, 1]
    por, phi = Porosity(tall, 1), np.zeros(tall.shape)
    por.measure(particles([1.5e-3, 1.5e-3, 8e-3 / 6], 1e-3), phi)
    assert phi[0, 0, 0] == pytest.approx(1.0 - sphere_volume(1e-3) / (3 * sphere_volume(1.5e-3)), rel=1e-14)
    assert (phi.ravel()[1:] == 1.0).all()


def test_an_elongated_cell_gives_a_lattice_its_solid_fraction():
    """The lattice of test_simple_cubic_lattice_gives_its_solid_fraction in cells of 3 x 3 x 6
    mm, each sampled in two spheres of R = 1.5 mm: averaged over 4^3 offsets of the lattice
    the middle layer's cells hold its solid fraction within the same Poisson-summation bound
    (each sphere's error is within it, so their mean is): the sampled volume is the parts'
    together (a cell taking one sphere's volume for its two would be off by a factor 2)."""
    a, r = 1e-3, 0.4e-3
    s = sphere_volume(r) / a**3
    grid = FluidGrid(np.zeros(3), np.array([3e-3, 3e-3, 6e-3]), (4, 4, 3), np.array([True, True, False]))
    assert sampling_parts(grid).tolist() == [1, 1, 2]
    sites = np.arange(12) * a
    base = np.array(list(itertools.product(sites, sites, np.arange(18) * a)))
    por, phi = Porosity(grid, len(base)), np.zeros(grid.shape)
    solid = []
    for offset in itertools.product(*[(np.arange(4) + 0.5) / 4 * a] * 3):
        por.measure(particles(base + offset, r), phi)
        solid.append(1.0 - phi[:, :, 1])
    worst = np.abs(np.mean(solid, axis=0) - s).max()
    assert worst <= aliasing_bound(a, 4, grid.sampling_radius, r), worst


def random_bed(rng, count=400):
    grid = make_grid((5, 4, 6), 0.006)
    pos = rng.uniform(0.0, 1.0, (count, 3)) * [0.03, 0.024, 0.036]
    return grid, particles(pos, rng.uniform(0.0008, 0.003, count), vel=rng.standard_normal((count, 3)))


def test_results_do_not_depend_on_the_thread_count_and_no_solid_is_counted_twice():
    grid, p = random_bed(np.random.default_rng(7))
    outputs = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        fields = np.zeros(grid.shape), np.zeros(grid.shape + (3,)), np.zeros(grid.shape)
        Porosity(grid, p.pos.shape[0]).measure(p, *fields)
        outputs.append(fields)
    for one, two in zip(*outputs, strict=True):
        assert np.array_equal(one, two)
    # the sampling spheres (diameter = cell edge) do not overlap, so the sampled solid never
    # exceeds the particles' volume (with the periodic images)
    sampled = np.sum(1.0 - outputs[0][0]) * sphere_volume(grid.sampling_radius)
    assert 0.0 < sampled <= np.sum(sphere_volume(p.radius))


def test_one_thread_bins_the_particles_without_a_parallel_region(monkeypatch):
    """physics/fluid/porosity.py bin_in_cells: on one thread the serial twin of bin_particles
    (kernels/serial.py) bins the particles, the parallel kernel on more; the same cells."""
    from sphere_cli.physics.fluid import porosity as module

    grid, p = random_bed(np.random.default_rng(3))
    cells = {}
    for threads in (1, 2):
        numba.set_num_threads(threads)
        cells[threads] = particle_cells(grid, p.pos, np.zeros(p.pos.shape[0], dtype=np.int64))

    def parallel(*arguments):
        raise AssertionError("the parallel kernel was called")

    monkeypatch.setattr(module, "bin_particles", parallel)
    numba.set_num_threads(1)
    Porosity(grid, p.pos.shape[0]).measure(p, np.zeros(grid.shape))
    assert np.array_equal(cells[1], cells[2])
    if numba.config.NUMBA_NUM_THREADS > 1:
        numba.set_num_threads(2)
        with pytest.raises(AssertionError, match="parallel kernel"):
            particle_cells(grid, p.pos, np.zeros(p.pos.shape[0], dtype=np.int64))


def test_overlapping_particles_clamp_at_zero_and_are_counted(caplog):
    grid = make_grid((2, 2, 2), 0.004)
    centre = [0.002, 0.002, 0.002]
    p = particles([centre, centre], 0.002)  # two particles filling the same sampling sphere
    phi = np.zeros(grid.shape)
    por = Porosity(grid, 2)
    with caplog.at_level("WARNING", logger="sphere.fluid.porosity"):
        assert por.measure(p, phi) == 1
        por.measure(p, phi)
    assert phi[0, 0, 0] == 0.0 and por.clamped_cells == 1
    assert len([r for r in caplog.records if "clamped to 0" in r.getMessage()]) == 1


def test_kernels_without_jit_agree():
    code = (
        "import numpy as np\n"
        "from types import SimpleNamespace\n"
        "from sphere_cli.physics.fluid.grid import FluidGrid\n"
        "from sphere_cli.physics.fluid.porosity import Porosity\n"
        "g = FluidGrid(np.zeros(3), np.full(3, 0.01), (2, 2, 3), np.array([True, True, False]))\n"
        "rng = np.random.default_rng(3)\n"
        "p = SimpleNamespace(pos=rng.uniform(0, 0.02, (6, 3)), vel=rng.standard_normal((6, 3)),\n"
        "                    radius=rng.uniform(0.001, 0.004, 6))\n"
        "phi = np.zeros(g.shape); vbar = np.zeros(g.shape + (3,))\n"
        "Porosity(g, 6).measure(p, phi, vbar)\n"
        "print(repr(phi.ravel().tolist() + vbar.ravel().tolist()))\n"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, check=True
    )
    pure = np.array(ast.literal_eval(out.stdout.strip()))
    namespace: dict = {}
    exec(code.replace("print(repr(phi.ravel().tolist() + vbar.ravel().tolist()))\n", ""), namespace)
    jitted = np.concatenate([namespace["phi"].ravel(), namespace["vbar"].ravel()])
    assert np.abs(pure - jitted).max() <= 1e-12


@pytest.mark.parametrize("periodic", [False, True])
def test_a_rank_is_sent_the_particles_its_slab_of_cells_can_reach(periodic):
    """Porosity.needed_by, the window of a split run (physics/rank_steps.py _near): 8 x planes
    of 1 mm cut 0-3 | 3-5 | 5-8 among 3 ranks; sampling spheres of 0.5 mm and particles of at
    most 0.5 mm reach one plane either side, so rank 1 needs the particles binned in planes 2-5;
    ranks 0 and 2 reach around the periodic x axis, not across a bounded one."""
    grid = FluidGrid(np.zeros(3), np.full(3, 0.001), (8, 2, 2), np.array([periodic, True, False]))
    porosity = Porosity(grid, 8)

    class Comm:
        def Get_rank(self):
            return 0

    porosity.slabs = Slabs(grid.shape, Comm(), np.array([0, 3, 5, 8]), periodic)
    pos = np.column_stack([(np.arange(8) + 0.5) * 0.001, np.full(8, 0.0005), np.full(8, 0.0005)])
    marks = porosity.needed_by(pos, 0.0005)
    reached = [set(np.flatnonzero(marks[rank])) for rank in range(3)]
    assert reached[1] == {2, 3, 4, 5}
    assert reached[0] == ({0, 1, 2, 3, 7} if periodic else {0, 1, 2, 3})
    assert reached[2] == ({4, 5, 6, 7, 0} if periodic else {4, 5, 6, 7})


@pytest.mark.parametrize("periodic", [(True, True, False), (False, True, True)])
def test_bins_beyond_reach_are_skipped_without_losing_a_particle(periodic):
    """The sampling sphere (R = 2 mm in 4 mm cells) and particles of up to 1.2 mm reach 3.2 mm,
    so of the 27 bins around a cell the kernel reads the 13 within that distance: not the
    corners (3.46 mm away) nor the bins above and below the edge columns (3.46 mm); the edge
    columns themselves (2.83 mm) it reads. Against the lens volumes of every particle and every
    periodic image, summed directly, with particles beyond every face (a bounded axis bins them
    at its ends): a bin skipped wrongly drops whole particles from the sums."""
    rng = np.random.default_rng(11)
    shape, edge = (4, 3, 5), 0.004
    grid = make_grid(shape, edge, periodic=periodic)
    size = np.array(shape) * edge
    count = 800
    pos = rng.uniform(-0.1, 1.1, (count, 3)) * size
    radius = rng.uniform(0.0001, 0.0012, count)
    vel = rng.standard_normal((count, 3))
    phi, vbar = np.zeros(grid.shape), np.zeros(grid.shape + (3,))
    Porosity(grid, count).measure(particles(pos, radius, vel), phi, vbar)

    big_r = grid.sampling_radius
    lens = np.vectorize(lambda r, d: lens_volume(big_r, r, d))
    shifts = np.array(list(itertools.product(*[(-1, 0, 1) if p else (0,) for p in periodic]))) * size
    images = (np.where(periodic, np.mod(pos, size), pos)[None] + shifts[:, None]).reshape(-1, 3)
    image_radius, image_vel = np.tile(radius, len(shifts)), np.tile(vel, (len(shifts), 1))
    solid, moment = np.zeros(grid.shape), np.zeros(grid.shape + (3,))
    for cell in itertools.product(*(range(n) for n in shape)):
        volumes = lens(image_radius, np.linalg.norm(images - (np.array(cell) + 0.5) * edge, axis=1))
        solid[cell], moment[cell] = volumes.sum(), volumes @ image_vel
    assert np.abs(phi - np.maximum(1.0 - solid / sphere_volume(big_r), 0.0)).max() <= 1e-13
    assert (phi < 0.9).sum() > 30 and (phi == 0.0).sum() < 3  # solid in most cells, few clamped
    assert np.abs(vbar - moment / solid[..., None]).max() <= 1e-12
