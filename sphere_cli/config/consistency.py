"""Rules that involve several keys at once, each reported against the key it is about.

Checked on the case alone (no scene is built): walls against periodic axes, the box against
the particles, placements against the box, schedules that can never fire.
"""

from __future__ import annotations

from .schema import Case, FilePlacement

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
            problems.append(
                (
                    ("walls", i, "face"),
                    f"axis {wall.face[0]} is periodic (domain.periodic); it cannot have a wall",
                )
            )
        if wall.face in seen:
            problems.append((("walls", i, "face"), f"walls[{seen[wall.face]}] is already on this face"))
        seen[wall.face] = i

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

    frames = case.output.frames
    if frames.every_time is None and frames.every_steps is None and frames.every_wall_minutes is None:
        problems.append((("output", "frames"), "set every_time, every_steps or every_wall_minutes"))
    return problems
