"""Case-file schema of `[fluid] model = "vans1d"`: a vertical profile of a streamwise (x) flow
over a granular bed in a laterally periodic cell (YADE HydroForceEngine-like, see
physics/fluid/vans1d.py). The flow is either solved (two-way coupling) or prescribed (one way).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .base import Count, Flag, Real, Strict
from .fluid_common import CouplingConfig


class SolvedFlow(Strict):
    """The 1D streamwise momentum balance of the fluid, solved (two-way coupling)."""

    kind: Literal["solved"] = "solved"
    mixing_length: Literal["none", "prandtl", "parabolic", "li-sawamoto"] = Field(
        "li-sawamoto",
        description=(
            'Eddy viscosity nu_t = l^2 |du/dz| with the mixing length l: "none" (laminar), "prandtl" '
            'l = kappa s, "parabolic" l = kappa s sqrt(1 - s/H) (s: height above the fluid bottom, H: '
            'flow depth), "li-sawamoto" l = kappa * integral of (c_max - c)/c_max dz from the bottom '
            "(c: the solid fraction, c_max: packed_solid_fraction), 0 in the layers at or below the "
            "highest one that reaches c_max, which damps it inside the bed (Li & Sawamoto 1995; "
            "the packed rule of YADE's HydroForceEngine) [-]."
        ),
    )
    kappa: Real = Field(0.41, gt=0, le=1, description="von Karman constant [-].")
    van_driest: Real = Field(
        0.0,
        ge=0,
        description=(
            "A+ of van Driest's damping of the mixing length in the viscous sublayer of a smooth "
            "floor, l (1 - exp(-z+/A+)) with z+ = (l/kappa) u*/nu and u* from the largest fluid "
            "shear stress; 26 is the classic value; 0 = no damping [-]."
        ),
    )
    viscous_sublayer: Real = Field(
        0.0,
        ge=0,
        description=(
            "YADE's viscous sublayer (HydroForceEngine viscousSubLayer): no eddy viscosity below "
            "the height z+ nu/u* above the floor, with this z+ and u* = sqrt(|S| H/rho_f) the "
            "friction velocity of the driving S = rho_f g_x - dp/dx over the depth H; 11.3 is "
            "YADE's value; 0 = none. Exclusive with van_driest [-]."
        ),
    )
    top: Literal["free-surface", "no-slip"] = Field(
        "free-surface",
        description=(
            'Boundary at fluid.surface: "free-surface" (no shear stress) or "no-slip" (a fixed lid: a '
            'channel between two walls; laminar only, mixing_length = "none") [-].'
        ),
    )
    top_velocity: Real = Field(
        0.0,
        description=(
            'Streamwise velocity of the lid with top = "no-slip" (a plane Couette flow when there '
            "is no other driving; YADE's uTop) [m/s]."
        ),
    )
    pressure_gradient: Real = Field(
        0.0,
        description=(
            "Imposed streamwise pressure gradient dp/dx driving the flow besides gravity's x "
            "component (negative pushes towards +x) [Pa/m]."
        ),
    )
    dt: Real = Field(
        1.0e-5,
        gt=0,
        description=(
            "Fluid time step (implicit in time, so it sets accuracy, not stability); each coupling "
            "interval is split into equal steps no longer than this [s]."
        ),
    )
    initial: Literal["rest", "steady"] = Field(
        "steady",
        description=(
            'Fluid velocity at t = 0: "rest", or "steady": the steady profile over the initial bed '
            "(particles held fixed while it is found) [-]."
        ),
    )

    @model_validator(mode="after")
    def _one_sublayer_treatment(self):
        if self.van_driest > 0.0 and self.viscous_sublayer > 0.0:
            raise ValueError(
                "van_driest and viscous_sublayer are two treatments of the same viscous sublayer: "
                "give one of them (the other 0)"
            )
        return self

    @model_validator(mode="after")
    def _a_lid_to_move(self):
        if self.top_velocity != 0.0 and self.top != "no-slip":
            raise ValueError('top_velocity moves a lid: it needs top = "no-slip"')
        return self

    @model_validator(mode="after")
    def _lid_is_laminar(self):
        if self.top == "no-slip" and self.mixing_length != "none":
            raise ValueError(
                'top = "no-slip" (a channel between two walls) is laminar only: the mixing lengths '
                'are measured from the bottom; set mixing_length = "none"'
            )
        return self


class LogLawFlow(Strict):
    """A prescribed logarithmic profile u = (u*/kappa) ln((z - bed_level)/roughness_length),
    0 below bed_level + roughness_length (one-way coupling)."""

    kind: Literal["log-law"]
    friction_velocity: Real = Field(gt=0, description="Friction velocity u* [m/s].")
    bed_level: Real = Field(description="Height of the log law's origin (the bed surface) [m].")
    roughness_length: Real = Field(gt=0, description="Roughness length z0 where u = 0 [m].")
    kappa: Real = Field(0.41, gt=0, le=1, description="von Karman constant [-].")


def _check_points(z: list, values: list, name: str) -> None:
    """A profile given at points: as many values as heights, the heights increasing strictly."""
    if len(z) != len(values):
        raise ValueError(f"z has {len(z)} points but {name} has {len(values)}")
    if any(b <= a for a, b in zip(z, z[1:], strict=False)):
        raise ValueError("z must increase strictly")


class ProfileFlow(Strict):
    """A prescribed profile u(z), linear between the given points and constant beyond the first
    and last one (one-way coupling)."""

    kind: Literal["profile"]
    z: list[Real] = Field(min_length=2, description="Heights of the points, increasing [m].")
    u: list[Real] = Field(min_length=2, description="Streamwise fluid velocity at each height [m/s].")

    @model_validator(mode="after")
    def _matching(self):
        _check_points(self.z, self.u, "u")
        return self


Flow = Annotated[SolvedFlow | LogLawFlow | ProfileFlow, Field(discriminator="kind")]


class ImposedSolidFraction(Strict):
    """A solid-fraction profile c(z) imposed on the fluid, linear between the given points and
    constant beyond the first and last one."""

    z: list[Real] = Field(min_length=2, description="Heights of the points, increasing [m].")
    value: list[Real] = Field(min_length=2, description="Solid fraction at each height, in [0, 1) [-].")

    @model_validator(mode="after")
    def _matching(self):
        _check_points(self.z, self.value, "value")
        outside = [v for v in self.value if not 0.0 <= v < 1.0]
        if outside:
            raise ValueError(f"solid fraction {outside[0]!r}: expected 0 <= value < 1")
        return self


class TurbulentFluctuations(Strict):
    """Turbulent velocity fluctuations seen by the particles, a discrete random walk (YADE's
    HydroForceEngine turbulentFluctuationZDep; Maurin et al. 2015): each particle above the bed
    draws a fluctuation (u', v', w') = u*_l (r3, r2, r1) with r1, r2 standard normal and
    r3 = -r1 + r4 (correlated: <u'w'> = -u*_l^2, the Reynolds shear stress over rho, and
    <u'^2> = 2 <w'^2>) or r3 standard normal, u*_l = sqrt(R_xz / rho) from the solved profile's
    Reynolds stress at its height, and keeps it for an eddy lifetime 0.33 kappa z_b / u*_l
    (z_b its height above the bed, at least 11.6 nu / u*_l; at most 10 s)."""

    bed_elevation: Real = Field(
        description=(
            "Height of the bed surface: particles whose centre lies at or below it see no "
            "fluctuation, and the lifetime's depth is measured from it [m]."
        )
    )
    seed: int = Field(
        0,
        ge=0,
        le=2**64 - 1,
        description=(
            "Seed of the draws: each particle's n-th draw is a fixed function of (seed, particle "
            "index, n), so runs do not depend on the thread count and a resume continues them [-]."
        ),
    )
    correlated: Flag = Field(
        True,
        description=(
            "Streamwise and wall-normal fluctuations correlated as the Reynolds shear stress "
            "demands (YADE's default, after Nezu 1977); false: independent [-]."
        ),
    )


class Vans1dFluid(Strict):
    """A 1D vertical fluid velocity profile coupled to the particles (bedload transport)."""

    model: Literal["vans1d"] = Field(description="Selects this fluid model.")
    density: Real = Field(1000.0, gt=0, description="Fluid density rho_f [kg/m^3].")
    viscosity: Real = Field(1.0e-6, gt=0, description="Kinematic viscosity nu of the fluid [m^2/s].")
    surface: Real = Field(
        description=(
            'Height of the free surface (or of the lid with top = "no-slip"); the fluid fills '
            "domain.lower z .. surface, which must lie inside the box [m]."
        )
    )
    cells: Count = Field(
        100, ge=2, description="Number of layers (fluid cells) between the bottom and the surface [-]."
    )
    stretching: Real = Field(
        1.0,
        ge=1.0,
        description=(
            "Thickness of the top layer over that of the bottom layer; layer thicknesses grow "
            "geometrically (1 = regular mesh) [-]."
        ),
    )
    flow: Flow = Field(
        default_factory=SolvedFlow, description="How the fluid velocity is found: solved or prescribed."
    )
    solid_fraction: ImposedSolidFraction | None = Field(
        None,
        description=(
            "A solid-fraction profile imposed on the fluid instead of the particles' layer average "
            "(as YADE's HydroForceEngine with phiPart set by the user): the fluid's (1 - c) factors, "
            "the Li-Sawamoto mixing length and the drag's hindrance take it; the particles' "
            "velocity and drag are still averaged from them. Default: the particles' average [-]."
        ),
    )
    coupling: CouplingConfig = Field(
        default_factory=CouplingConfig,
        description=(
            "Time between two fluid updates (default: interval = 1e-3 s): the particles move this "
            "long in a frozen profile, then the solid profiles are averaged and the fluid advanced "
            "over the same time."
        ),
    )
    drag_exponent: Real = Field(
        3.1,
        ge=0,
        le=10,
        description=(
            "Richardson-Zaki exponent n of the hindrance (1 - c)^-n in the drag coefficient "
            "C_d = (0.44 + 24/Re_p)(1 - c)^-n, c the solid fraction; measured ones lie between "
            "2.4 (inertial) and 4.65 (viscous) [-]."
        ),
    )
    packed_solid_fraction: Real = Field(
        0.61,
        gt=0,
        lt=1,
        description=(
            "Solid fraction of the packed bed: the Li-Sawamoto mixing length vanishes at it, and "
            "the hindrance uses the solid fraction up to it [-]."
        ),
    )
    buoyancy: Literal["wall-normal", "full"] = Field(
        "wall-normal",
        description=(
            '"full": -rho_f V g; "wall-normal": only its z part, for a steady uniform flow whose '
            "pressure has no streamwise gradient [-]."
        ),
    )
    fluctuations: TurbulentFluctuations | None = Field(
        None,
        description=(
            "Turbulent velocity fluctuations added to the fluid velocity each particle's forces "
            'see (a discrete random walk, YADE\'s); needs flow.kind = "solved" (its Reynolds '
            "stress). Default: none [-]."
        ),
    )
    lift_coefficient: Real = Field(
        0.0,
        ge=0,
        description=(
            "C_L of the lift 0.5 rho_f C_L (pi d^2/4) (u_r,top^2 - u_r,bottom^2) along z, from the "
            "relative velocity at the top and the bottom of the particle (Wiberg & Smith 1985; 0.2 "
            "in their work); 0 = no lift [-]."
        ),
    )
    materials: list[str] = Field(
        default_factory=list,
        description=(
            "Names of the materials (from `materials`) whose particles feel the fluid; empty = "
            "every particle [-]."
        ),
    )
    ids: tuple[int, int] | None = Field(
        None,
        description=(
            "Only the particles of index first..last (both included, 0-based, in placement order: "
            "a placement file's rows) feel the fluid, as YADE's HydroForceEngine ids; with "
            "materials, those in both; default: every particle [-]."
        ),
    )

    @field_validator("ids")
    @classmethod
    def _an_id_range(cls, ids):
        if ids is not None and not 0 <= ids[0] <= ids[1]:
            raise ValueError(f"{list(ids)}: expected [first, last] with 0 <= first <= last")
        return ids

    def case_problems(self, case, shape, count: int | None) -> list[tuple[tuple, str]]:
        """What this fluid requires of the rest of the case (config/consistency.py): a laterally
        periodic cell, gravity in the x-z plane, the surface inside the box, materials that
        particles are made of, particle ids below `count` (None where a placement file counts
        them: the build checks them then). shape: no grid (None)."""
        from .consistency import particle_materials  # (which imports the schema, and so this)

        materials = list(particle_materials(case))
        problems = []
        periodic = case.domain.periodic
        if not (periodic[0] and periodic[1]) or periodic[2]:
            problems.append(
                (
                    ("domain", "periodic"),
                    "the vans1d fluid is a vertical profile of a laterally periodic cell: it needs "
                    "periodic = [true, true, false]",
                )
            )
        if case.domain.gravity[1] != 0.0:
            problems.append(
                (
                    ("domain", "gravity"),
                    "the vans1d fluid flows along x: gravity must have no y component (tilt it in x-z)",
                )
            )
        bottom, top = case.domain.lower[2], case.domain.upper[2]
        if not bottom < self.surface <= top:
            problems.append(
                (
                    ("fluid", "surface"),
                    f"the fluid surface must lie inside the box, above its bottom z = {bottom:g} m and at "
                    f"most at its top z = {top:g} m",
                )
            )
        unknown = [name for name in self.materials if name not in materials]
        if unknown:
            problems.append(
                (
                    ("fluid", "materials"),
                    f"{unknown}: no particle is made of it (particles.material names {materials or 'none'})",
                )
            )
        if self.fluctuations is not None and not isinstance(self.flow, SolvedFlow):
            problems.append(
                (
                    ("fluid", "fluctuations"),
                    'need flow.kind = "solved": their magnitude is the solved profile\'s Reynolds stress',
                )
            )
        if count is not None and (problem := self.ids_problem(count)):
            problems.append((("fluid", "ids"), problem))
        return problems

    def ids_problem(self, count: int) -> str | None:
        """What is wrong with fluid.ids for a scene of `count` particles (None: nothing)."""
        if self.ids is None or self.ids[1] < count:
            return None
        first, last = self.ids
        return f"[{first}, {last}]: the scene has {count} particles (0 .. {count - 1})"
