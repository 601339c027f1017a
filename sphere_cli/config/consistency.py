"""Rules that involve several keys at once, each reported against the key it is about.

Checked on the case alone (no scene is built): walls against periodic axes, the box against
the particles, placements against the box, materials against the contact law and the names
that refer to them, schedules that can never fire.
"""

from __future__ import annotations

import math

from .fluid_grid import grid_cells
from .schema import LAW_KEYS, Case, FilePlacement

AXIS = {"x": 0, "y": 1, "z": 2}


def check_consistency(case: Case) -> list[tuple[tuple, str]]:
    problems: list[tuple[tuple, str]] = []
    dom = case.domain
    extent = [hi - lo for lo, hi in zip(dom.lower, dom.upper, strict=True)]
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

    for ax in range(3):
        if extent[ax] < diameter:
            problems.append(
                (
                    ("domain", "upper"),
                    f"the box is {extent[ax]:g} m along {'xyz'[ax]}, smaller than the "
                    f"largest particle diameter {diameter:g} m",
                )
            )
        elif dom.periodic[ax] and extent[ax] < 2.0 * diameter:
            problems.append(
                (
                    ("domain", "periodic"),
                    f"a periodic axis must be at least two largest diameters long "
                    f"({2 * diameter:g} m); {'xyz'[ax]} is {extent[ax]:g} m",
                )
            )

    placement = case.particles.placement
    if isinstance(placement, FilePlacement):
        if case.particles.count is not None:
            problems.append(
                (("particles", "count"), "the count comes from the placement file; remove this key")
            )
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

    problems += _material_problems(case)
    problems += _fluid_grid_problems(case, extent, diameter)

    frames = case.output.frames
    if frames.every_time is None and frames.every_steps is None and frames.every_wall_minutes is None:
        problems.append((("output", "frames"), "set every_time, every_steps or every_wall_minutes"))
    return problems


def _fluid_grid_problems(case: Case, extent: list[float], diameter: float) -> list[tuple[tuple, str]]:
    """The fluid grid against the largest particle the radius distribution can make (radii
    read from a placement file are checked when the scene is built)."""
    grid = getattr(case.fluid, "grid", None)
    if grid is None or isinstance(case.particles.placement, FilePlacement):
        return []
    _, key, problem = grid_cells(grid, extent, diameter)
    return [] if problem is None else [(("fluid", "grid", key), problem)]


def particle_materials(case: Case) -> dict[str, float]:
    """Name -> number fraction of the materials particles are made of ({} for the single-material
    form, particles.density with the properties of [contact])."""
    spec = case.particles.material
    if spec is None:
        return {}
    if isinstance(spec, str):
        return {spec: 1.0}
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
                problems.append((loc, f"no material of this name in [[materials]] (known: {sorted(names)})"))
                continue
            used[name] = loc
            if not fraction > 0:
                problems.append((loc, "a number fraction must be > 0"))
            if case.materials[names[name]].density is None:
                problems.append(
                    (("materials", names[name], "density"), "required: particles are made of this material")
                )
        if not isinstance(spec, str) and not math.isclose(sum(fractions.values()), 1.0, abs_tol=1e-9):
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
                    f"no material of this name in [[materials]] (known: {sorted(names)})",
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
                        f"no material {name!r} in [[materials]] (known: {sorted(names)})",
                    )
                )
        key = frozenset(pair.materials)
        if key in seen:
            problems.append(
                (("contact", "pairs", i, "materials"), f"contact.pairs[{seen[key]}] already sets this pair")
            )
        seen.setdefault(key, i)
    return problems


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
        if any(hi <= lo for lo, hi in zip(group.region_lower, group.region_upper, strict=True)):
            problems.append(((*loc, "region_upper"), "must exceed region_lower along every axis"))
    return problems
