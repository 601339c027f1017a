"""Rules that involve several keys at once, each reported against the key it is about.

Checked on the case alone (no scene is built): walls against periodic axes, the box against
the particles, placements against the box, materials against the contact law and the names
that refer to them, what a fluid model requires of the rest of the case (each fluid table's
`case_problems`), schedules that can never fire, and sizes that cannot fit: more spheres than
the region holds, more memory than the machine has (memory.py), more steps than the clock counts.
Also the warnings of `case_warnings`: allowed, but probably not meant.
"""

from __future__ import annotations

import math
import os

from .fluid_grid import follow_warnings, grid_cells
from .memory import memory_problems
from .schema import LAW_KEYS, Case, FilePlacement, LognormalRadius

AXIS = {"x": 0, "y": 1, "z": 2}
# equal spheres fill at most pi/sqrt(18) of space (Kepler's conjecture, proved by Hales 2005)
DENSEST_PACKING = math.pi / math.sqrt(18.0)
# Clock.time is step * dt in float64: beyond 2^53 steps the step count is no longer exact there,
# and successive steps share one time
MAX_STEPS = 2**53
# more steps than this are allowed but warned of: days of run time even for a few particles
MANY_STEPS = 1e9
# lognormal radii outside [min, max] are redrawn (scene/radii.py): at most this many draws
MAX_RADIUS_DRAWS = 1e9
# the cells along one axis of a fluid grid whose centres the fluid's rules look at before the build
# (more: the build looks at them)
MAX_CHECKED_CELLS = 2**22


def check_consistency(case: Case) -> list[tuple[tuple, str]]:
    if not case.has_particles:
        return _fluid_only_problems(case)
    problems: list[tuple[tuple, str]] = []
    dom = case.domain
    diameter = 2.0 * case.particles.radius.largest

    seen: dict[str, int] = {}
    for i, wall in enumerate(case.walls):
        axis = AXIS[wall.face[0]]
        if dom.periodic[axis]:
            what = "stress control" if wall.mode == "stress" else "a wall"
            problems.append(
                (
                    ("walls", i, "face"),
                    f"axis {wall.face[0]} is periodic (domain.periodic); it cannot have {what}",
                )
            )
        if wall.face in seen:
            problems.append((("walls", i, "face"), f"walls[{seen[wall.face]}] is already on this face"))
        seen[wall.face] = i
        problems += wall_motion_problems(wall, ("walls", i))
    problems += _stage_problems(case, seen)
    problems += _group_problems(case)
    if getattr(case.fluid, "bed", None) is not None:
        problems.append(
            (
                ("fluid", "bed"),
                "a bed of imposed porosity is for a case without particles (no [particles] or "
                "count = 0); with particles the porosity comes from them",
            )
        )

    placement = case.particles.placement
    if not isinstance(placement, FilePlacement):  # a file's radii are checked once read
        problems += box_problems(case, diameter)

    if isinstance(placement, FilePlacement):
        if case.particles.count is not None:
            problems.append(
                (("particles", "count"), "the count comes from the placement file; remove this key")
            )
        problems += memory_problems(case, 0, None)  # the particles are counted once read
    else:
        if case.particles.count is None:
            problems.append((("particles", "count"), "required for lattice and random placement"))
        lower = placement.region_lower or dom.lower
        upper = placement.region_upper or dom.upper
        for key, corner in (
            ("region_lower", placement.region_lower),
            ("region_upper", placement.region_upper),
        ):
            if corner is None:
                continue
            if any(
                c < lo - 1e-12 or c > hi + 1e-12
                for c, lo, hi in zip(corner, dom.lower, dom.upper, strict=True)
            ):
                problems.append((("particles", "placement", key), "must lie inside the domain box"))
        if any(hi - lo < diameter for lo, hi in zip(lower, upper, strict=True)):
            problems.append(
                (
                    ("particles", "placement"),
                    f"the placement region is smaller than one particle diameter ({diameter:g} m)",
                )
            )
        if case.particles.count is not None:
            problems += _size_problems(case, lower, upper)

    if case.contact is None:
        problems.append((("contact",), "required key is missing (the particles need a contact law)"))
    else:
        problems += _material_problems(case)
    from_file = isinstance(placement, FilePlacement)
    problems += fluid_problems(
        case, None if from_file else diameter, None if from_file else case.particles.count
    )
    problems += _path_problems(case)
    problems += _step_problems(case)
    problems += _frame_problems(case)
    return problems


def _frame_problems(case: Case) -> list[tuple[tuple, str]]:
    frames = case.output.frames
    if frames.every_time is None and frames.every_steps is None and frames.every_wall_minutes is None:
        return [(("output", "frames"), "set every_time, every_steps or every_wall_minutes")]
    return []


# what a fluid-only scene has not, in the messages that refuse keys which need particles
_NO_PARTICLES = "this scene has no particles (no [particles], or particles.count = 0)"


def _fluid_only_problems(case: Case) -> list[tuple[tuple, str]]:
    """A scene without particles: only with a fluid, which then runs alone; nothing that acts
    on particles or measures them, and a fluid that needs nothing of them."""
    if case.fluid is None:
        if "particles" not in case.model_fields_set:
            return [
                (
                    ("particles",),
                    "required key is missing: a scene needs particles unless it has a [fluid] "
                    "section (a fluid-only scene)",
                )
            ]
        return [
            (
                ("particles", "count"),
                "no particles is a fluid-only scene, which needs a [fluid] section; give at least 1 "
                "particle or add [fluid]",
            )
        ]
    problems: list[tuple[tuple, str]] = []
    if case.particles.placement.method == "file":
        problems.append(
            (
                ("particles", "count"),
                "the count comes from the placement file; remove this key (or the placement, "
                "for a fluid-only scene)",
            )
        )
    if case.walls:
        problems.append((("walls",), f"walls act on particles only and {_NO_PARTICLES}; remove [[walls]]"))
    if case.stages:
        problems.append(
            (("stages",), f"stages drive walls and particles, and {_NO_PARTICLES}; remove [[stages]]")
        )
    if case.output.fields:
        problems.append(
            (("output", "fields"), f"{_NO_PARTICLES}: there are no per-particle fields; remove this key")
        )
    if case.simulation.device == "cuda":
        problems.append(
            (
                ("simulation", "device"),
                f"the GPU steps particles (a fluid's own step runs on the CPU) and {_NO_PARTICLES}; "
                'use device = "cpu" (the default)',
            )
        )
    if case.output.observables.quantities:
        problems.append(
            (
                ("output", "observables", "quantities"),
                f"these measure the particles and {_NO_PARTICLES}; remove this key (the fluid's "
                "own observables are always recorded)",
            )
        )
    grid = getattr(case.fluid, "grid", None)
    if grid is not None and grid.cells is None and grid.cell_size is None:
        problems.append(
            (
                ("fluid", "grid"),
                "give cells or cell_size: the default cell edge is three largest particle diameters, "
                f"and {_NO_PARTICLES}",
            )
        )
    permeability = getattr(case.fluid, "permeability", None)
    if getattr(permeability, "model", None) == "kozeny-carman" and permeability.coefficient is None:
        problems.append(
            (
                ("fluid", "permeability", "coefficient"),
                "required key is missing: its default d^2/180 takes d from the particles, and "
                f'{_NO_PARTICLES}; give it, or a constant permeability (model = "constant")',
            )
        )
    problems += fluid_problems(case, 0.0, 0)
    problems += memory_problems(case, 0, None)  # the fluid alone
    problems += _step_problems(case)
    problems += _frame_problems(case)
    return problems


def box_problems(case: Case, diameter: float) -> list[tuple[tuple, str]]:
    """The box against the largest particle diameter [m]: each side at least one, a periodic
    side at least two (the case's radius distribution, or the radii of a placement file)."""
    problems: list[tuple[tuple, str]] = []
    dom = case.domain
    for ax in range(3):
        extent = dom.upper[ax] - dom.lower[ax]
        if extent < diameter:
            problems.append(
                (
                    ("domain", "upper"),
                    f"the box is {extent:g} m along {'xyz'[ax]}, smaller than the "
                    f"largest particle diameter {diameter:g} m",
                )
            )
        elif dom.periodic[ax] and extent < 2.0 * diameter:
            problems.append(
                (
                    ("domain", "periodic"),
                    f"a periodic axis must be at least two largest diameters long "
                    f"({2 * diameter:g} m); {'xyz'[ax]} is {extent:g} m",
                )
            )
    return problems


def fluid_problems(case: Case, diameter: float | None, count: int | None) -> list[tuple[tuple, str]]:
    """The fluid grid against the largest particle `diameter` [m] (its cells at least that
    wide, for the porosity estimate), and what the fluid model requires of the rest of the case
    (each model's `case_problems`), so that `sphere validate` refuses them too. diameter and the
    particles' `count`: None where a placement file has them and is not read here (the grid's
    cells are then known only where the case sets them; the fluid model checks them again at
    its build, which `sphere validate` makes too: scene/builder.py check_build)."""
    fluid = case.fluid
    rules = getattr(fluid, "case_problems", None)  # a fluid table without rules has none
    if fluid is None or rules is None:
        return []
    grid, shape = getattr(fluid, "grid", None), None  # (the 1D VANS column has no grid)
    if grid is not None and (grid.cells is not None or grid.cell_size is not None or diameter):
        dom = case.domain
        extent = [hi - lo for lo, hi in zip(dom.lower, dom.upper, strict=True)]
        cells, key, problem = grid_cells(grid, extent, diameter or 0.0)
        if problem is not None:
            return [(("fluid", "grid", key), problem)]
        shape = cells if max(cells) <= MAX_CHECKED_CELLS else None
    return rules(case, shape, count)


def _size_problems(case: Case, lower, upper) -> list[tuple[tuple, str]]:
    """Counts of a lattice or random placement that cannot fit the region, the memory or the
    drawing of the radii (the exact lattice capacity is checked when the scene is built)."""
    problems: list[tuple[tuple, str]] = []
    count = case.particles.count
    dist = case.particles.radius
    volume = math.prod(hi - lo for lo, hi in zip(lower, upper, strict=True))
    equal = dist.smallest == dist.largest
    # unequal spheres pack denser than equal ones, without a simple bound but the space itself
    fraction = DENSEST_PACKING if equal else 1.0
    r = dist.smallest
    solid = count * 4.0 / 3.0 * math.pi * r * r * r  # not r**3: that raises on overflow
    if solid > fraction * volume:
        problems.append(
            (
                ("particles", "count"),
                f"{count} spheres of radius {'' if equal else 'at least '}{dist.smallest:g} m fill "
                f"{solid:.3g} m^3, more than the {volume:.3g} m^3 placement region holds"
                + (f" even at the densest packing ({DENSEST_PACKING:.1%})" if equal else ""),
            )
        )
    problems += memory_problems(case, count, dist.largest)
    if isinstance(dist, LognormalRadius):
        # the share of ln(r) ~ N(ln median, sigma^2) in [min, max], on either side of the median
        erf = [
            math.erf((math.log(r) - math.log(dist.median)) / (dist.sigma * math.sqrt(2.0)))
            for r in (dist.min, dist.max)
        ]
        kept = 0.5 * (erf[1] - erf[0])
        draws = count / kept if kept > 0 else math.inf
        if draws > MAX_RADIUS_DRAWS:
            problems.append(
                (
                    ("particles", "radius"),
                    f"min and max keep {kept:.2g} of the lognormal distribution, so drawing {count} "
                    f"radii (those outside are redrawn) would take about {draws:.2g} draws; widen "
                    "[min, max] or raise sigma",
                )
            )
    return problems


def _path_problems(case: Case) -> list[tuple[tuple, str]]:
    """File names the operating system cannot open (the only path key is the placement file's)."""
    placement = case.particles.placement
    if not isinstance(placement, FilePlacement):
        return []
    loc = ("particles", "placement", "path")
    encoded = os.fsencode(placement.path)
    if b"\0" in encoded:
        return [(loc, "a file name cannot hold the NUL character")]
    try:
        name_max, path_max = os.pathconf(".", "PC_NAME_MAX"), os.pathconf(".", "PC_PATH_MAX")
    except (ValueError, OSError, AttributeError):  # not POSIX: the POSIX minimum of Linux
        name_max, path_max = 255, 4096
    longest = max(len(name) for name in encoded.split(b"/"))
    if len(encoded) >= path_max or longest > name_max:
        return [
            (
                loc,
                f"{len(encoded)} bytes long, its longest name {longest} bytes: this system opens "
                f"paths of less than {path_max} bytes, with names of at most {name_max}",
            )
        ]
    return []


def _step_problems(case: Case) -> list[tuple[tuple, str]]:
    sim = case.simulation
    if sim.dt == "auto":  # checked when the scene is built and dt is known
        return []
    problem = step_problem(sim.duration, sim.dt)
    return [] if problem is None else [(("simulation", "dt"), problem)]


def step_problem(duration: float, dt: float) -> str | None:
    """Why steps of `dt` cannot reach `duration` [s] (None if they can)."""
    steps = duration / dt if dt > 0 else math.inf  # an "auto" dt can underflow to 0
    if steps <= MAX_STEPS:
        return None
    many = f"{steps:.3g}" if math.isfinite(steps) else "more than 1e+308"
    return (
        f"{duration:g} s in steps of {dt:.3g} s take {many} steps, more than 2^53, beyond "
        "which the float64 time of a step is no longer exact; is dt in seconds?"
    )


def case_warnings(case: Case) -> list[tuple[tuple, str]]:
    """Values that are allowed but probably not meant, each against its key (dt = "auto" is
    judged when the scene is built and its limits are known)."""
    sim = case.simulation
    warnings = []
    if sim.dt != "auto" and sim.duration / sim.dt > MANY_STEPS:
        warnings.append(
            (
                ("simulation", "dt"),
                f"the run takes {sim.duration / sim.dt:.3g} steps to reach duration = {sim.duration:g} s",
            )
        )
    grid = getattr(case.fluid, "grid", None)
    if grid is not None and case.has_particles:
        warnings += follow_warnings(grid, case)
    return warnings


def particle_materials(case: Case) -> dict[str, float]:
    """Name -> number fraction of the materials particles are made of ({} for the single-material
    form, particles.density with the properties of [contact])."""
    spec = case.particles.material
    if spec is None:
        return {}
    if isinstance(spec, str):
        return {spec: 1.0}
    if isinstance(spec, list):  # a placement file's column says which: no fractions
        return dict.fromkeys(spec, 1.0 / len(spec)) if spec else {}
    return dict(spec)


def _material_problems(case: Case) -> list[tuple[tuple, str]]:
    problems: list[tuple[tuple, str]] = []
    law = case.contact.model
    own_keys = LAW_KEYS[law]
    other_keys = [k for m, keys in LAW_KEYS.items() if m != law for k in keys]
    names: dict[str, int] = {}
    for i, material in enumerate(case.materials):
        if material.name in names:
            problems.append(
                (("materials", i, "name"), f"materials[{names[material.name]}] already has this name")
            )
        names.setdefault(material.name, i)
        for key in other_keys:
            if getattr(material, key) is not None:
                problems.append(
                    (
                        ("materials", i, key),
                        f'not used by the contact model "{law}" (it needs {" and ".join(own_keys)})',
                    )
                )

    known = _known(names)  # once: a message per unknown name must not sort them all again
    used: dict[str, tuple] = {}  # material name -> where it is used
    fractions = particle_materials(case)
    spec = case.particles.material
    if spec is None:
        if case.particles.density is None:
            problems.append(
                (("particles", "density"), "required key is missing (or give particles.material)")
            )
    else:
        if case.particles.density is not None:
            problems.append(
                (("particles", "density"), "the density comes from the material (particles.material)")
            )
        for name, fraction in fractions.items():
            loc = ("particles", "material") if isinstance(spec, str) else ("particles", "material", name)
            if name not in names:
                problems.append((loc, f"no material of this name in [[materials]] ({known})"))
                continue
            used[name] = loc
            if not fraction > 0:
                problems.append((loc, "a number fraction must be > 0"))
            if case.materials[names[name]].density is None:
                problems.append(
                    (("materials", names[name], "density"), "required: particles are made of this material")
                )
        if isinstance(spec, list):
            if len(set(spec)) != len(spec) or not spec:
                problems.append((("particles", "material"), "expected a list of distinct material names"))
            if not isinstance(case.particles.placement, FilePlacement):
                problems.append(
                    (
                        ("particles", "material"),
                        "a list of names needs a placement file whose material column says which particle "
                        "is made of which; give a name or a table of number fractions",
                    )
                )
        elif not isinstance(spec, str) and not math.isclose(sum(fractions.values()), 1.0, abs_tol=1e-9):
            problems.append(
                (("particles", "material"), f"the number fractions sum to {sum(fractions.values())!r}, not 1")
            )
    for i, wall in enumerate(case.walls):
        if wall.material is None:
            continue
        if wall.material not in names:
            problems.append(
                (
                    ("walls", i, "material"),
                    f"no material of this name in [[materials]] ({known})",
                )
            )
        else:
            used.setdefault(wall.material, ("walls", i, "material"))

    # the law's elastic properties: from the material or, as a default, from [contact]
    required = ("normal_stiffness",) if law == "linear" else own_keys
    for key in required:
        if getattr(case.contact, key) is not None:
            continue
        if spec is None:
            problems.append((("contact", key), f'required key is missing (the "{law}" model needs it)'))
        for name in used:
            if getattr(case.materials[names[name]], key) is None:
                problems.append(
                    (
                        ("materials", names[name], key),
                        f"required: this material is in use and [contact] gives no default {key}",
                    )
                )

    seen: dict[frozenset, int] = {}
    for i, pair in enumerate(case.contact.pairs):
        for name in pair.materials:
            if name not in names:
                problems.append(
                    (
                        ("contact", "pairs", i, "materials"),
                        f"no material {name!r} in [[materials]] ({known})",
                    )
                )
        key = frozenset(pair.materials)
        if key in seen:
            problems.append(
                (("contact", "pairs", i, "materials"), f"contact.pairs[{seen[key]}] already sets this pair")
            )
        seen.setdefault(key, i)
    return problems


def _known(names) -> str:
    listed = sorted(names)
    if len(listed) > 10:
        return f"known: {listed[:10]} and {len(listed) - 10} more"
    return f"known: {listed}"


def wall_motion_problems(motion, loc: tuple) -> list[tuple[tuple, str]]:
    """Keys of a wall's mode (a [[walls]] or [[stages.walls]] table) that contradict each other."""
    problems: list[tuple[tuple, str]] = []
    mode = motion.mode
    if mode == "velocity" and motion.velocity is None:
        problems.append(((*loc, "velocity"), 'required key is missing (mode = "velocity" needs it)'))
    if mode != "velocity" and motion.velocity is not None:
        problems.append(((*loc, "velocity"), f'only for mode = "velocity"; this wall has mode = "{mode}"'))
    if mode == "stress":
        if motion.stress is None:
            problems.append(((*loc, "stress"), 'required key is missing (mode = "stress" needs it)'))
        sine = {k: getattr(motion, k) is not None for k in ("stress_amplitude", "frequency")}
        if any(sine.values()) and not all(sine.values()):
            have, lack = (
                ("stress_amplitude", "frequency")
                if sine["stress_amplitude"]
                else ("frequency", "stress_amplitude")
            )
            problems.append(((*loc, have), f"a sinusoidal modulation needs {lack} as well"))
        if motion.phase is not None and not sine["stress_amplitude"]:
            problems.append(
                ((*loc, "phase"), "only with a sinusoidal modulation (stress_amplitude, frequency)")
            )
    else:
        for key in type(motion).STRESS_KEYS:
            if getattr(motion, key) is not None:
                problems.append(((*loc, key), f'only for mode = "stress"; this wall has mode = "{mode}"'))
    if motion.shear_velocity is not None and motion.shear_stress is not None:
        problems.append(
            ((*loc, "shear_stress"), "contradicts shear_velocity: the tangential motion is one or the other")
        )
    shearing = motion.shear_velocity is not None or motion.shear_stress is not None
    if shearing and motion.shear_axis is None:
        problems.append(
            ((*loc, "shear_axis"), "required key is missing (shear_velocity/shear_stress need it)")
        )
    if motion.shear_axis is not None:
        if not shearing:
            problems.append(((*loc, "shear_axis"), "needs shear_velocity or shear_stress"))
        face = getattr(motion, "face", None)
        if face is not None and motion.shear_axis == face[0]:
            problems.append(
                ((*loc, "shear_axis"), f"must be tangential to the wall; {face} is normal to {face[0]}")
            )
    if not motion.driven:
        for key in ("mass", "damping"):
            if getattr(motion, key) is not None:
                problems.append(
                    ((*loc, key), 'only for a stress-driven wall (mode = "stress" or shear_stress)')
                )
    return problems


def _stage_problems(case: Case, walls: dict[str, int]) -> list[tuple[tuple, str]]:
    problems: list[tuple[tuple, str]] = []
    periodic = case.domain.periodic
    for s, stage in enumerate(case.stages):
        stop = stage.stop_when
        criteria = []
        if stop is not None:
            criteria = [
                k
                for k in ("kinetic_energy_below", "displacement", "shear_displacement")
                if getattr(stop, k) is not None
            ]
            if stop.min_time > 0 and stop.kinetic_energy_below is None:
                problems.append((("stages", s, "stop_when", "min_time"), "only with kinetic_energy_below"))
            if (stop.displacement is not None or stop.shear_displacement is not None) and stop.wall is None:
                problems.append(
                    (
                        ("stages", s, "stop_when", "wall"),
                        "required key is missing (the displacement criteria need it)",
                    )
                )
            if stop.wall is not None:
                if stop.wall not in walls:
                    problems.append(
                        (("stages", s, "stop_when", "wall"), "no wall on this face (walls[].face)")
                    )
                if stop.displacement is None and stop.shear_displacement is None:
                    problems.append(
                        (("stages", s, "stop_when", "wall"), "needs displacement or shear_displacement")
                    )
        if stage.duration is None and not criteria:
            problems.append(
                (
                    ("stages", s),
                    "a stage needs a stop condition: duration, or stop_when with kinetic_energy_below, "
                    "displacement or shear_displacement",
                )
            )
        seen: dict[str, int] = {}
        for j, wall in enumerate(stage.walls):
            loc = ("stages", s, "walls", j)
            axis = AXIS[wall.face[0]]
            if periodic[axis]:
                what = "stress control" if wall.mode == "stress" else "a wall"
                problems.append(
                    (
                        (*loc, "face"),
                        f"axis {wall.face[0]} is periodic (domain.periodic); it cannot have {what}",
                    )
                )
            elif wall.face not in walls:
                problems.append(((*loc, "face"), "no wall on this face (add it to [[walls]])"))
            if wall.face in seen:
                problems.append(
                    ((*loc, "face"), f"stages[{s}].walls[{seen[wall.face]}] already sets this wall")
                )
            seen.setdefault(wall.face, j)
            problems += wall_motion_problems(wall, loc)
    return problems


def _group_problems(case: Case) -> list[tuple[tuple, str]]:
    problems: list[tuple[tuple, str]] = []
    for g, group in enumerate(case.particles.groups):
        loc = ("particles", "groups", g)
        if group.motion == "velocity" and group.velocity is None:
            problems.append(((*loc, "velocity"), 'required key is missing (motion = "velocity" needs it)'))
        if group.motion != "velocity" and group.velocity is not None:
            problems.append(((*loc, "velocity"), f'only for motion = "velocity", not "{group.motion}"'))
        if (group.region_lower is None) != (group.region_upper is None):
            key = "region_upper" if group.region_upper is None else "region_lower"
            problems.append(((*loc, key), "required key is missing (a region needs both corners)"))
        elif group.region_lower is None and group.name is None:
            problems.append(
                (
                    loc,
                    "give a region (region_lower, region_upper), a name for a placement file's "
                    "group column, or both",
                )
            )
        elif group.region_lower is not None and any(
            hi <= lo for lo, hi in zip(group.region_lower, group.region_upper, strict=True)
        ):
            problems.append(((*loc, "region_upper"), "must exceed region_lower along every axis"))
        if group.name is not None:
            first = next(h for h, other in enumerate(case.particles.groups) if other.name == group.name)
            if first != g:
                problems.append(((*loc, "name"), f"particles.groups[{first}] already has this name"))
    return problems
