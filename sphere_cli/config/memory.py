"""The memory a scene will take, estimated from the case before anything is allocated, against the
memory there is: a scene that cannot fit is refused naming the key that makes it big (checked
with the case by consistency.py, and by scene/builder.py once a placement file gives the
particles) instead of failing part-way through allocating it.

Only the arrays that grow with the scene are counted; Python, Numba and the compiled kernels take
some 0.3 GiB besides. The limit is the physical memory of the machine, or SPHERE_MEMORY_GIB (to
check a case on a login node for a larger compute node, say).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from ..errors import UsageError
from .fluid_grid import grid_cells
from .schema import Case, RandomPlacement

GIB = 2**30
LIMIT_VARIABLE = "SPHERE_MEMORY_GIB"
# Every array the time loop keeps per particle, neighbour lists and scratch included: 780 to
# 1020 B measured on a settled bed with six walls on 1 and 2 threads (docs/performance.md). What
# the builder needs besides (radii, placement) is less, and freed before the loop.
PARTICLE_BYTES = 1024
# the cells of the neighbour search and of random insertion: one int64 per cell
GRID_CELL_BYTES = 8
# The neighbour search gives every cell its entry while the cells number at most this many per
# particle (plus DENSE_FLOOR); beyond, it lists only the occupied ones (physics/neighbors.py), and
# random insertion coarsens its cells to this many per particle (scene/packing.py): a settled bed
# fills ~1 cell per 10 particles, so only a box mostly empty goes the sparse way.
CELLS_PER_PARTICLE = 8
DENSE_FLOOR = 4096
# random placement draws every candidate position at once: 3 float64, held twice while sorted
CANDIDATE_BYTES = 48
# fluid state, scratch and pressure solver per cell: 336 B measured for Navier-Stokes and 296 B
# for Darcy (48^3 cells, tracemalloc over the build and a few steps); vans1d layers alike
FLUID_CELL_BYTES = 400
# the neighbour lists hold particle indices as int32
MAX_PARTICLES = 2**31 - 1


@dataclass(frozen=True)
class _Part:
    nbytes: float
    loc: tuple  # the key that makes this part as big as it is
    what: str
    transient: bool = False  # freed before the time loop starts (placement)
    particles: float = 0.0  # particles it holds


def memory_limit() -> tuple[float, str]:
    """The bytes a scene may take, and where that number comes from."""
    text = os.environ.get(LIMIT_VARIABLE)
    if text is None:
        try:
            return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "physical memory of this machine"
        except (ValueError, OSError, AttributeError):  # no sysconf (not POSIX): no check
            return math.inf, "unknown memory"
    try:
        gib = float(text)
    except ValueError:
        gib = math.nan
    if not (math.isfinite(gib) and gib > 0):
        raise UsageError(f"{LIMIT_VARIABLE} = {text!r}: expected a positive number of GiB")
    return gib * GIB, f"{LIMIT_VARIABLE} = {text}"


def memory_problems(
    case: Case, count: int, largest: float | None, count_loc: tuple = ("particles", "count")
) -> list[tuple[tuple, str]]:
    """Problems of a scene of `count` particles of largest radius `largest` [m] (the key
    `count_loc` gives them) that cannot fit in memory or in the int32 indices. With `largest`
    None (a placement file not yet read) only what the case alone sizes is counted: the fluid."""
    parts = _parts(case, count, largest, count_loc)
    persistent = sum(p.nbytes for p in parts if not p.transient)
    peak = max(persistent, sum(p.nbytes for p in parts if p.transient))
    limit, source = memory_limit()
    if peak > limit:
        big = max(parts, key=lambda p: p.nbytes)
        return [
            (
                big.loc,
                f"{big.what}: the scene would need {_size(peak)} of memory, more than the "
                f"{limit / GIB:.3g} GiB of {source}"
                + ("" if source.startswith(LIMIT_VARIABLE) else f" ({LIMIT_VARIABLE} sets another limit)"),
            )
        ]
    particles = sum(p.particles for p in parts)
    if particles > MAX_PARTICLES:
        return [
            (
                count_loc,
                f"{particles:.4g} particles (rough walls included): at most {MAX_PARTICLES}, "
                "which the int32 indices of the neighbour lists can address",
            )
        ]
    return []


def _parts(case: Case, count: int, largest: float, count_loc: tuple) -> list[_Part]:
    dom = case.domain
    length = [hi - lo for lo, hi in zip(dom.lower, dom.upper, strict=True)]
    parts = [_fluid_part(case, length, largest)] if case.fluid is not None else []
    if largest is None:
        return [p for p in parts if p is not None]
    parts.append(
        _Part(count * PARTICLE_BYTES, count_loc, f"{count:.3g} particles at ~1 KiB each", particles=count)
    )
    for w, wall in enumerate(case.walls):
        if wall.rough is not None:  # a square lattice on the wall (scene/walls.py rough_layers)
            pitch = wall.rough.spacing * 2.0 * (wall.rough.radius or largest)
            axis = "xyz".index(wall.face[0])
            glued = math.prod(length[b] / pitch + 1.0 for b in range(3) if b != axis)
            parts.append(
                _Part(
                    glued * PARTICLE_BYTES,
                    ("walls", w, "rough"),
                    f"{glued:.3g} spheres glued to the {wall.face} wall at ~1 KiB each",
                    particles=glued,
                )
            )
    # cells of two largest radii plus the skin, each listed while there are few per particle,
    # else only the occupied ones (physics/neighbors.py)
    reach = (2.0 + case.simulation.neighbor_skin) * largest
    listed = min(_cells(length, reach), CELLS_PER_PARTICLE * float(count) + DENSE_FLOOR)
    parts.append(
        _Part(
            listed * GRID_CELL_BYTES,
            ("domain", "upper"),
            f"the neighbour search lists {listed:.3g} of the {_shape(length, reach)} cells of "
            f"{reach:.3g} m (two largest radii and the skin) that cut the box",
        )
    )
    placement = case.particles.placement
    if isinstance(placement, RandomPlacement):
        attempts = placement.max_attempts
        parts.append(
            _Part(
                float(count) * attempts * CANDIDATE_BYTES,
                ("particles", "placement"),
                f"random placement draws all {attempts} candidate positions (max_attempts) of each of "
                f"the {count:.3g} particles at once",
                transient=True,
            )
        )
        lower = placement.region_lower or dom.lower
        upper = placement.region_upper or dom.upper
        region = [hi - lo for lo, hi in zip(lower, upper, strict=True)]
        parts.append(
            _Part(
                min(_cells(region, 2.0 * largest), CELLS_PER_PARTICLE * float(count)) * GRID_CELL_BYTES,
                ("particles", "placement"),
                "random insertion cuts the region into cells of one largest diameter, at most "
                f"{CELLS_PER_PARTICLE} per particle",
                transient=True,
            )
        )
    return [p for p in parts if p is not None]


def _fluid_part(case: Case, length: list[float], largest: float | None) -> _Part | None:
    """The fluid's cells (None where they depend on radii not known yet)."""
    fluid = case.fluid
    grid = getattr(fluid, "grid", None)
    if grid is None:  # vans1d: a column of layers
        return _Part(
            float(fluid.cells) * FLUID_CELL_BYTES,
            ("fluid", "cells"),
            f"{fluid.cells} fluid layers at ~{FLUID_CELL_BYTES} B each",
        )
    if largest is None and grid.cells is None:  # cells sized by the particles
        return None
    shape, key, _ = grid_cells(grid, length, 2.0 * (largest or 0.0))
    cells = math.prod(float(n) for n in shape)
    return _Part(
        cells * FLUID_CELL_BYTES,
        ("fluid", "grid", key),
        f"a fluid grid of {' x '.join(map(str, shape))} cells at ~{FLUID_CELL_BYTES} B each",
    )


def _along(length: list[float], cell: float) -> list[float]:
    """Cells of edge at least `cell` along each axis, as the grids cut them (inf if too many)."""
    return [max(1.0, float(math.floor(n))) if math.isfinite(n) else n for n in (L / cell for L in length)]


def _cells(length: list[float], cell: float) -> float:
    return math.prod(_along(length, cell))


def _shape(length: list[float], cell: float) -> str:
    return " x ".join(f"{n:.0f}" if n < 1e15 else f"{n:.3g}" for n in _along(length, cell))


def _size(nbytes: float) -> str:
    gib = nbytes / GIB
    return f"about {gib:.3g} GiB" if gib < 1e300 else "more than 1e+300 GiB"
