"""The case-file schema: every key a case may hold, its unit, its default and its bounds.

SI units everywhere. `extra = "forbid"` makes a typo an error rather than a silent default.
Each physics option is a tagged union (`model = "..."`, `distribution = "..."`,
`method = "..."`), so the validated case says exactly which physics runs.
Cross-field rules (walls against periodic axes, particles against the box) live in
`consistency.py`, where each error can name the key it is about.
"""

from __future__ import annotations

from collections import Counter
from typing import Annotated, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from .base import FACES, Count, Flag, Real, Strict, Vec3, _default_tag
from .fluid_darcy import DarcyFluid
from .fluid_navier_stokes import NavierStokesFluid
from .fluid_vans1d import Vans1dFluid

__all__ = ["FACES", "Count", "Flag", "Real", "Strict", "Vec3"]


class Simulation(Strict):
    """Time stepping and when to stop."""

    duration: Real = Field(gt=0, description="Simulated time to reach, to the nearest whole step [s].")
    dt: float | Literal["auto"] = Field(
        "auto",
        description=(
            'Time step [s], or "auto": dt_safety times the stability limit of one contact alone '
            "(each collision resolved by ~25 steps or more), but at most 0.9 times the stability "
            "bound of the scene (spheres held by many contacts at once, driven walls, the fluid). "
            "Without particles, 0.9 times the fluid's limit, or the fluid.coupling.interval that "
            "sets it. A number above that bound is refused (see `stability`)."
        ),
    )
    dt_safety: Real = Field(
        0.08,
        gt=0,
        le=1,
        description='Fraction of the stability limit of one contact alone that dt = "auto" takes [-].',
    )
    stability: Literal["packing", "contact"] = Field(
        "packing",
        description=(
            'Which stability limit a given dt must respect: "packing", the bound for spheres held '
            'by as many contacts as any packing allows (a true bound); or "contact", the limit of '
            "one contact alone, for a scene that never packs densely (a dense packing may then "
            'grow unstable, which stops the run with exit 70). dt = "auto" respects both.'
        ),
    )
    threads: Count | None = Field(
        None,
        ge=1,
        description=(
            "Numba threads (default: one per 500 particles, 8000 where threads sleep between "
            "parallel regions: OMP_WAIT_POLICY=PASSIVE or the workqueue or tbb threading layer; "
            "at least one; a navier-stokes or darcy grid's own step one per 2048 cells, 32768 "
            "where they sleep; particles placed from a file are counted from it first; never more than "
            "NUMBA_NUM_THREADS). Set, every part of the step takes it. Results do not depend on it."
        ),
    )
    neighbor_skin: Real = Field(
        0.2,
        gt=0,
        le=2,
        description=(
            "Verlet-list skin as a fraction of the largest radius [-]. Affects speed only: "
            "results are the same for any skin. Default 0.2: within 2 % of the fastest of 0.4, "
            "0.2 and 0.1 on both a pour and a resting bed, where 0.4 was up to 30 % slower "
            "(docs/performance.md)."
        ),
    )
    device: Literal["cpu", "cuda"] = Field(
        "cpu",
        description=(
            'Where the steps run: "cpu" (every model), or "cuda", an NVIDIA GPU (needs the CUDA '
            "extra, pip install 'sphere-cli[cuda]'), for particles with pair contacts, gravity, plane "
            "walls (fixed, moving or stress-controlled), stages, periodic boundaries, the energy "
            "budget and the fluids' action on the particles (the fluid's own step runs on the CPU at "
            "each coupling step) so far (a case with a fluid without particles is refused). The GPU "
            "agrees with the CPU to round-off; "
            "`sphere run --device` overrides this key."
        ),
    )
    rank_balance: Literal["particles", "time"] = Field(
        "particles",
        description=(
            "How a scene split across MPI ranks (`mpiexec -n N sphere run`) cuts its slabs at each "
            'neighbour-list build: "particles", each rank holding as many particles (ghosts '
            'counted); "time", as much work, each rank\'s particles weighted by its measured force '
            "time per particle since the last build (for beds whose cost per particle differs "
            "between regions: dense and loose, walls). Affects speed only: results are the same for "
            "any cut. Ignored on one rank."
        ),
    )
    blowup_check_every: Count = Field(
        100,
        ge=1,
        description="Steps between checks for NaN and runaway velocities [-].",
    )

    @field_validator("dt", mode="before")
    @classmethod
    def _positive_dt(cls, value):
        if value == "auto":
            return value
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise ValueError('expected a positive number of seconds or "auto"')
        try:
            return float(value)
        except OverflowError:  # an integer of hundreds of digits
            raise ValueError("too large for a number of seconds") from None


class Domain(Strict):
    """The simulation box: an axis-aligned box, each axis either walled/open or periodic."""

    lower: Vec3 = Field((0.0, 0.0, 0.0), description="Lower corner of the box [m].")
    upper: Vec3 = Field(description="Upper corner of the box [m].")
    periodic: tuple[Flag, Flag, Flag] = Field(
        (False, False, False), description="Periodic boundary along x, y, z."
    )
    gravity: Vec3 = Field((0.0, 0.0, -9.81), description="Gravitational acceleration [m/s^2].")

    @model_validator(mode="after")
    def _ordered(self):
        for ax, lo, hi in zip("xyz", self.lower, self.upper, strict=True):
            if not hi > lo:
                raise ValueError(f"upper {ax} ({hi}) must exceed lower {ax} ({lo})")
        return self


_WALL_MODE = (
    'How the wall moves along its normal: "fixed" (in place), "velocity" (at `velocity`) or '
    '"stress" (a rigid body of mass `mass` driven towards the normal stress `stress`, '
    "optionally modulated by a sine; see the user guide for the control law)."
)


class WallMotion(Strict):
    """How a wall moves: its normal mode and an optional tangential (shear) drive. The keys a mode
    does not use must be left out (a contradiction is an error)."""

    mode: Literal["fixed", "velocity", "stress"] = Field("fixed", description=_WALL_MODE)
    velocity: Real | None = Field(
        None, description='Normal velocity of a "velocity" wall, positive into the box [m/s].'
    )
    stress: Real | None = Field(
        None,
        gt=0,
        description='Target normal stress of a "stress" wall, compressive positive (mean of the sine) [Pa].',
    )
    stress_amplitude: Real | None = Field(
        None,
        gt=0,
        description=(
            "Amplitude of a sinusoidal modulation of the target stress, "
            "stress + stress_amplitude sin(2 pi frequency t + phase), t from the start of the stage [Pa]."
        ),
    )
    frequency: Real | None = Field(None, gt=0, description="Frequency of the modulation [Hz].")
    phase: Real | None = Field(None, description="Phase of the modulation at the start of the stage [rad].")
    shear_axis: Literal["x", "y", "z"] | None = Field(
        None, description="Axis of the tangential motion (not the wall's own axis)."
    )
    shear_velocity: Real | None = Field(
        None, description="Prescribed tangential velocity along shear_axis [m/s]."
    )
    shear_stress: Real | None = Field(
        None,
        description=(
            "Target shear stress along shear_axis, the traction the wall exerts on the particles; "
            "the wall is driven tangentially like a stress wall [Pa]."
        ),
    )
    mass: Real | None = Field(
        None,
        gt=0,
        description=(
            "Mass of a stress-driven wall (default: one layer of mean particles covering the wall, "
            "m_mean A / d_mean^2) [kg]."
        ),
    )
    damping: Real | None = Field(
        None,
        gt=0,
        description=(
            "Damping of a stress-driven wall as a fraction of critical damping against the bed, "
            "estimated as H/d_mean layers of contacts in series, each k A/d_mean^2 (H: distance "
            "to the opposite wall when the mode is set; default 1) [-]."
        ),
    )

    STRESS_KEYS: ClassVar[tuple[str, ...]] = ("stress", "stress_amplitude", "frequency", "phase")

    @property
    def driven(self) -> bool:
        """True if the wall obeys a force balance (normal or tangential stress control)."""
        return self.mode == "stress" or self.shear_stress is not None

    @property
    def moves(self) -> bool:
        return self.mode != "fixed" or self.shear_velocity is not None or self.shear_stress is not None


class RoughLayer(Strict):
    """Spheres glued to a wall (a square lattice with their centres on the plane), moving with it."""

    radius: Real | None = Field(
        None, gt=0, description="Radius of the glued spheres (default: the largest particle radius) [m]."
    )
    spacing: Real = Field(
        1.0,
        ge=1.0,
        description=(
            "Centre spacing as a multiple of their diameter; stretched so that a whole number fits "
            "each side of the wall (the period along a periodic axis) [-]."
        ),
    )


class _WallFace(Strict):
    face: Literal["x-", "x+", "y-", "y+", "z-", "z+"] = Field(
        description='Face of the box the wall lies on: "x-", "x+", "y-", "y+", "z-" or "z+".'
    )


class Wall(WallMotion, _WallFace):
    """A plane wall on one face of the box, its normal pointing into the box. Its mode applies
    before the first stage (and throughout if there are no stages)."""

    friction: Real | None = Field(
        None, ge=0, description="Coulomb friction coefficient against particles (default: the contact's) [-]."
    )
    material: str | None = Field(
        None,
        description=(
            "Name of the wall's material (one of `materials`): its elasticity enters the contact (E*, "
            "G* or the linear stiffness) and its surface properties are mixed with the particle's. "
            "Default: a rigid wall with the particle material's own restitution, friction and "
            "rolling friction (and, for the linear law, its stiffness)."
        ),
    )
    rough: RoughLayer | None = Field(
        None,
        description=(
            "Make the wall rough: a layer of spheres of the first particle material glued to it. "
            "They are particles that move with the wall; the forces on them count as wall force."
        ),
    )


class _StageWallFace(Strict):
    face: Literal["x-", "x+", "y-", "y+", "z-", "z+"] = Field(
        description="Face of the wall (one of `walls`) whose mode this table sets."
    )


class StageWall(WallMotion, _StageWallFace):
    """The mode a wall takes from the start of a stage."""

    approach: Flag = Field(
        False,
        description=(
            "At the start of the stage, move the wall (with its rough layer) along its normal until it "
            "just touches the outermost free particle; then its mode applies."
        ),
    )


class StopWhen(Strict):
    """A stage ends as soon as any of these is met (checked every check_every steps)."""

    kinetic_energy_below: Real | None = Field(
        None, gt=0, description="Total kinetic energy of the particles below this [J]."
    )
    min_time: Real = Field(
        0.0,
        ge=0,
        description=(
            "Time into the stage before kinetic_energy_below is tested (a bed at rest at the start) [s]."
        ),
    )
    wall: Literal["x-", "x+", "y-", "y+", "z-", "z+"] | None = Field(
        None, description="Wall whose displacement the displacement criteria measure."
    )
    displacement: Real | None = Field(
        None,
        gt=0,
        description=(
            "Normal displacement of `wall` since the start of the stage, either way, reaching this [m]."
        ),
    )
    shear_displacement: Real | None = Field(
        None,
        gt=0,
        description="Tangential displacement of `wall` since the start of the stage reaching this [m].",
    )


class Stage(Strict):
    """One stage of a chained experiment (deposit, consolidate, shear, ...)."""

    name: str = Field("", description="Label used in the log and in the output.")
    duration: Real | None = Field(None, gt=0, description="Longest simulated time the stage runs [s].")
    stop_when: StopWhen | None = Field(None, description="Conditions that end the stage early.")
    check_every: Count = Field(100, ge=1, description="Steps between tests of the stop_when conditions [-].")
    friction: Real | None = Field(
        None,
        ge=0,
        description=(
            "Coulomb friction of every contact (particle pairs and walls) during this stage, e.g. 0 to "
            "prepare a dense packing (default: the contact tables) [-]."
        ),
    )
    walls: list[StageWall] = Field(
        default_factory=list,
        max_length=len(FACES),
        description=(
            "Wall modes from the start of this stage (at most one table per wall); walls not listed "
            "keep their mode."
        ),
    )


class ParticleGroup(Strict):
    """Particles given a prescribed motion: those whose centre starts inside a box-shaped region,
    and those a placement file's `group` column names it for."""

    name: str | None = Field(
        None,
        min_length=1,
        description="Name by which the `group` column of a placement file puts particles in this group.",
    )
    region_lower: Vec3 | None = Field(
        None, description="Lower corner of the region [m] (with region_upper; unset: no region)."
    )
    region_upper: Vec3 | None = Field(None, description="Upper corner of the region [m].")
    motion: Literal["fixed", "velocity"] = Field(
        description=(
            '"fixed": never moves; "velocity": moves at `velocity` without rotating. Such particles '
            "push others but nothing pushes them (walls neither touch nor feel them)."
        )
    )
    velocity: Vec3 | None = Field(None, description='Velocity of a "velocity" group [m/s].')


# --- particle radii -------------------------------------------------------------------------


class FixedRadius(Strict):
    distribution: Literal["fixed"] = "fixed"
    value: Real = Field(gt=0, description="Radius of every particle [m].")

    @property
    def largest(self) -> float:
        return self.value

    @property
    def smallest(self) -> float:
        return self.value


class UniformRadius(Strict):
    distribution: Literal["uniform"]
    min: Real = Field(gt=0, description="Smallest radius [m].")
    max: Real = Field(gt=0, description="Largest radius [m].")

    @model_validator(mode="after")
    def _ordered(self):
        if self.max < self.min:
            raise ValueError(f"max ({self.max}) must not be below min ({self.min})")
        return self

    @property
    def largest(self) -> float:
        return self.max

    @property
    def smallest(self) -> float:
        return self.min


class LognormalRadius(Strict):
    distribution: Literal["lognormal"]
    median: Real = Field(gt=0, description="Median radius [m].")
    sigma: Real = Field(gt=0, le=2, description="Standard deviation of ln(radius) [-].")
    min: Real = Field(gt=0, description="Radii below this are redrawn [m].")
    max: Real = Field(gt=0, description="Radii above this are redrawn [m].")

    @model_validator(mode="after")
    def _ordered(self):
        if not self.min <= self.median <= self.max:
            raise ValueError(f"need min <= median <= max, got {self.min}, {self.median}, {self.max}")
        return self

    @property
    def largest(self) -> float:
        return self.max

    @property
    def smallest(self) -> float:
        return self.min


class BimodalRadius(Strict):
    distribution: Literal["bimodal"]
    small: Real = Field(gt=0, description="Radius of the small species [m].")
    large: Real = Field(gt=0, description="Radius of the large species [m].")
    large_fraction: Real = Field(0.5, ge=0, le=1, description="Number fraction of large particles [-].")

    @property
    def largest(self) -> float:
        return max(self.small, self.large)

    @property
    def smallest(self) -> float:
        return min(self.small, self.large)


RadiusDistribution = Annotated[
    FixedRadius | UniformRadius | LognormalRadius | BimodalRadius,
    Field(discriminator="distribution"),
]

# --- particle placement ---------------------------------------------------------------------


class LatticePlacement(Strict):
    method: Literal["lattice"] = "lattice"
    spacing: Real = Field(
        1.2, ge=1.0, description="Lattice spacing as a multiple of the largest diameter [-]."
    )
    jitter: Real = Field(
        0.1,
        ge=0,
        le=1,
        description="Random offset of each site, as a fraction of the free gap between spheres [-].",
    )
    region_lower: Vec3 | None = Field(
        None, description="Lower corner of the filled region (default: the box) [m]."
    )
    region_upper: Vec3 | None = Field(
        None, description="Upper corner of the filled region (default: the box) [m]."
    )


class RandomPlacement(Strict):
    method: Literal["random"]
    region_lower: Vec3 | None = Field(
        None, description="Lower corner of the filled region (default: the box) [m]."
    )
    region_upper: Vec3 | None = Field(
        None, description="Upper corner of the filled region (default: the box) [m]."
    )
    max_attempts: Count = Field(
        200, ge=1, description="Candidate positions tried per particle before giving up [-]."
    )


class FilePlacement(Strict):
    method: Literal["file"]
    path: str = Field(
        description=(
            "CSV with a header of column names: x, y, z and optionally r, vx, vy, vz, wx, wy, wz "
            "(angular velocity), material (names from particles.material), group (names of "
            "particles.groups entries, empty for none) and fixed (1 or 0); or HDF5 with datasets "
            "position (N,3) and optionally radius (N,), velocity (N,3), angular_velocity (N,3), "
            "material and group (N,) strings and fixed (N,). Relative paths are relative to the "
            "case file."
        )
    )


Placement = Annotated[LatticePlacement | RandomPlacement | FilePlacement, Field(discriminator="method")]


class Particles(Strict):
    """The spheres: how many, how big, how dense, where."""

    count: Count | None = Field(
        None,
        ge=0,
        description=(
            "Number of particles (not used with placement from a file); 0, like leaving out "
            "[particles], makes a fluid-only scene, which needs a [fluid] section [-]."
        ),
    )
    density: Real | None = Field(
        None,
        gt=0,
        description=(
            "Density of every particle; required unless particles.material names the materials, "
            "which then give the density [kg/m^3]."
        ),
    )
    material: str | dict[str, Real] | list[str] | None = Field(
        None,
        description=(
            'What the particles are made of: the name of one of `materials` ("glass"), or a '
            "table of names and number fractions summing to 1 ({ glass = 0.7, steel = 0.3 }), "
            "assigned at random (seeded by particles.seed) in exact proportions, or a list of names "
            '(["glass", "steel"]) when the `material` column of a placement file says which '
            "particle is made of which (that column wins over fractions); material id k is the k-th "
            "name. Unset: one material, of density particles.density and with the properties of the "
            "contact table."
        ),
    )
    radius: RadiusDistribution = Field(
        default_factory=lambda: FixedRadius(value=1e-3),
        description=(
            "Radius distribution, or a number: every particle of that radius [m] (with a file, "
            "used only if the file has no radii)."
        ),
    )
    placement: Placement = Field(default_factory=LatticePlacement, description="Where the spheres start.")
    velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Initial velocity of every particle [m/s].")
    angular_velocity: Vec3 = Field(
        (0.0, 0.0, 0.0),
        description=(
            "Initial angular velocity of every particle (with a file, used only if the file has none) "
            "[rad/s]."
        ),
    )
    seed: Count = Field(0, ge=0, description="Seed of the random numbers for radii and positions [-].")
    overlap_tolerance: Real = Field(
        0.05,
        ge=0,
        le=0.5,
        description="Largest initial overlap accepted, as a fraction of the smaller radius [-].",
    )

    groups: list[ParticleGroup] = Field(
        default_factory=list,
        description="Groups of particles with a prescribed motion (the others are free); a later group wins.",
    )

    @model_validator(mode="before")
    @classmethod
    def _default_tags(cls, data):
        radius = data.get("radius") if isinstance(data, dict) else None
        if isinstance(radius, int | float) and not isinstance(radius, bool):  # one radius for all
            data = {**data, "radius": {"distribution": "fixed", "value": radius}}
        data = _default_tag(data, "radius", "distribution", "fixed")
        return _default_tag(data, "placement", "method", "lattice")


# --- contact law ----------------------------------------------------------------------------


_RESTITUTION = (
    "Normal coefficient of restitution e, in (0, 1]. The normal force is never attractive "
    "(F_n = max(0, elastic + dashpot)), so the contact ends when the force vanishes, before the "
    "overlap closes; the dashpot is calibrated for exactly that clamped contact, so the realised "
    "restitution is e (for the Hertz law at every impact speed) [-]."
)
_ROLLING = (
    "Rolling friction coefficient mu_r: a constant torque mu_r R* F_n against the relative "
    "rolling of the two bodies (Ai et al. 2011, model A), never reversing it; 0 = off [-]."
)


class ContactPair(Strict):
    """Properties of one pair of materials, replacing those the mixing rules would give."""

    materials: tuple[str, str] = Field(
        description="The two materials (names from `materials`; the same name twice for a like pair)."
    )
    restitution: Real | None = Field(None, gt=0, le=1, description="Restitution e of this pair [-].")
    friction: Real | None = Field(None, ge=0, description="Coulomb friction coefficient of this pair [-].")
    rolling_friction: Real | None = Field(
        None, ge=0, description="Rolling friction coefficient of this pair [-]."
    )


class LinearPair(ContactPair):
    normal_stiffness: Real | None = Field(None, gt=0, description="k_n of this pair [N/m].")
    tangential_stiffness: Real | None = Field(None, gt=0, description="k_t of this pair [N/m].")


class LinearContact(Strict):
    """Linear spring-dashpot normal force with an elastic tangential spring and Coulomb cap."""

    model: Literal["linear"] = "linear"
    normal_stiffness: Real | None = Field(
        None,
        gt=0,
        description=(
            "Normal spring constant k_n; required unless every material in use gives its own "
            "(values here are the defaults of every material) [N/m]."
        ),
    )
    tangential_stiffness: Real | None = Field(
        None, gt=0, description="Tangential spring constant k_t (default 2/7 k_n) [N/m]."
    )
    restitution: Real = Field(0.5, gt=0, le=1, description=_RESTITUTION)
    friction: Real = Field(0.5, ge=0, description="Coulomb friction coefficient mu [-].")
    rolling_friction: Real = Field(0.0, ge=0, description=_ROLLING)
    pairs: list[LinearPair] = Field(
        default_factory=list,
        description="Explicit properties of pairs of `materials`, instead of the mixing rules.",
    )

    @property
    def kt(self) -> float:
        if self.tangential_stiffness is None:
            return 2.0 / 7.0 * self.normal_stiffness
        return self.tangential_stiffness


class HertzMindlinContact(Strict):
    """Hertz normal force with a calibrated dashpot; Mindlin no-slip tangential spring and
    Coulomb cap."""

    model: Literal["hertz-mindlin"]
    youngs_modulus: Real | None = Field(
        None,
        gt=0,
        description=(
            "Young's modulus E; required unless every material in use gives its own (values here "
            "are the defaults of every material) [Pa]."
        ),
    )
    poisson_ratio: Real | None = Field(
        None, ge=0, le=0.5, description="Poisson's ratio nu (required like youngs_modulus) [-]."
    )
    restitution: Real = Field(0.5, gt=0, le=1, description=_RESTITUTION)
    friction: Real = Field(0.5, ge=0, description="Coulomb friction coefficient mu [-].")
    rolling_friction: Real = Field(0.0, ge=0, description=_ROLLING)
    pairs: list[ContactPair] = Field(
        default_factory=list,
        description="Explicit properties of pairs of `materials`, instead of the mixing rules.",
    )


ContactModel = Annotated[LinearContact | HertzMindlinContact, Field(discriminator="model")]

LAW_KEYS = {
    "linear": ("normal_stiffness", "tangential_stiffness"),
    "hertz-mindlin": ("youngs_modulus", "poisson_ratio"),
}


class Material(Strict):
    """A material particles or walls are made of. Contact properties left out take the value of
    the contact table."""

    name: str = Field(min_length=1, description="Name that particles.material and walls[].material use.")
    density: Real | None = Field(
        None, gt=0, description="Density (required for a material particles are made of) [kg/m^3]."
    )
    youngs_modulus: Real | None = Field(None, gt=0, description="Young's modulus E (hertz-mindlin) [Pa].")
    poisson_ratio: Real | None = Field(
        None, ge=0, le=0.5, description="Poisson's ratio nu (hertz-mindlin) [-]."
    )
    normal_stiffness: Real | None = Field(
        None, gt=0, description="k_n of a contact of two particles of this material (linear) [N/m]."
    )
    tangential_stiffness: Real | None = Field(
        None, gt=0, description="k_t of such a contact (linear; default 2/7 of its k_n) [N/m]."
    )
    restitution: Real | None = Field(None, gt=0, le=1, description="Restitution e [-].")
    friction: Real | None = Field(None, ge=0, description="Coulomb friction coefficient mu [-].")
    rolling_friction: Real | None = Field(None, ge=0, description="Rolling friction coefficient mu_r [-].")


# --- output ---------------------------------------------------------------------------------


class Schedule(Strict):
    """When something happens: at any of these intervals (whichever comes first)."""

    every_time: Real | None = Field(None, gt=0, description="Interval of simulated time [s].")
    every_steps: Count | None = Field(None, ge=1, description="Interval in time steps [-].")
    every_wall_minutes: Real | None = Field(None, gt=0, description="Interval of wall-clock time [min].")


class CheckpointSchedule(Schedule):
    every_wall_minutes: Real | None = Field(30.0, gt=0, description="Interval of wall-clock time [min].")
    keep: Count = Field(3, ge=1, description="Number of newest checkpoints kept [-].")


class Observables(Schedule):
    """Measurements written to /observables of trajectory.h5, computed only when due (the time
    loop does no measuring work between samples; the energy budget alone accumulates every step,
    and only when listed). Schedule keys left unset: a sample with every frame."""

    quantities: list[
        Literal[
            "energy",
            "contacts",
            "packing_fraction",
            "coordination",
            "stress",
            "profiles",
            "deformation",
            "energy_budget",
        ]
    ] = Field(
        default_factory=lambda: ["energy", "contacts"],
        description=(
            "Groups of observables to record: energy (kinetic, potential, elastic, total [J]); "
            "contacts (pair and wall contact counts); packing_fraction (solid fraction of the sample "
            "and of its interior [-]); coordination (mean contacts per particle in the interior, with "
            "and without rattlers [-]); stress (granular stress tensor of the sample, contact virial "
            "+ kinetic part, compression positive [Pa], pressure [Pa], effective friction "
            "tau/sigma_n [-]); profiles (solid fraction, stress tensor and mean velocity per horizontal "
            "layer); deformation (sample height [m], dilation [-]); energy_budget (work of gravity and "
            "walls, energy dissipated by damping, friction and rolling resistance, accumulated every "
            "step, and the balance residual [J])."
        ),
    )
    layers: Count = Field(
        10,
        ge=1,
        le=10000,
        description="Number of horizontal layers of the profiles over the sample height [-].",
    )
    interior_margin: Real = Field(
        2.0,
        ge=0,
        description=(
            "Thickness of the layer next to each wall and free surface left out of the interior "
            "region (interior packing fraction and coordination), in largest particle diameters [-]."
        ),
    )
    shear_direction: Literal["x", "y"] = Field(
        "x",
        description=(
            "Horizontal direction of shear for the effective friction tau/sigma_n = -sigma_zs/sigma_zz, "
            "s = this axis (z is the normal direction)."
        ),
    )

    @field_validator("quantities")
    @classmethod
    def _unique(cls, value):
        repeated = sorted(q for q, n in Counter(value).items() if n > 1)
        if repeated:
            raise ValueError(f"listed more than once: {', '.join(repeated)}")
        return value

    @property
    def follows_frames(self) -> bool:
        return self.every_time is None and self.every_steps is None and self.every_wall_minutes is None


class Output(Strict):
    frames: Schedule = Field(
        default_factory=lambda: Schedule(every_steps=1000),
        description="When trajectory frames are written (a first frame is always written at the start).",
    )
    checkpoints: CheckpointSchedule = Field(
        default_factory=CheckpointSchedule,
        description="When checkpoints are written (one is always written at the end).",
    )
    status_every_seconds: Real = Field(
        10.0, gt=0, description="Wall-clock interval of the status line and status.json [s]."
    )
    fields: list[Literal["velocity", "angular_velocity", "force", "torque"]] = Field(
        default_factory=lambda: ["velocity", "angular_velocity", "force"],
        description="Per-particle fields written in each frame besides position (radius is written once).",
    )
    observables: Observables = Field(
        default_factory=Observables,
        description=(
            "Which observables are recorded in trajectory.h5 and how often (default: energies "
            "and contact counts with every frame)."
        ),
    )


Fluid = Annotated[NavierStokesFluid | DarcyFluid | Vans1dFluid, Field(discriminator="model")]


class Case(Strict):
    """A complete case file."""

    title: str = Field("", description="Free text describing the case.")
    simulation: Simulation
    domain: Domain
    particles: Particles = Field(
        default_factory=lambda: Particles(count=0),
        description=(
            "Required unless the case has a [fluid] section: left out (or with count = 0), the "
            "scene is fluid-only and the fluid runs alone."
        ),
        json_schema_extra={"default_text": ""},  # the description says what leaving it out means
    )
    contact: ContactModel | None = Field(
        None,
        description="The contact law of the particles (required when there are particles).",
    )
    materials: list[Material] = Field(
        default_factory=list,
        description="Materials of particles and walls, referred to by name (one table per material).",
    )
    walls: list[Wall] = Field(
        default_factory=list,
        max_length=len(FACES),
        description="Plane walls, one table per wall (at most one on each face of the box).",
    )
    fluid: Fluid | None = Field(
        None,
        description="The fluid saturating the particles, if any (a dry scene has no [fluid] section).",
    )
    stages: list[Stage] = Field(
        default_factory=list,
        description=(
            "Stages run one after another in the same run (each ends on its duration or stop_when); "
            "the run ends with the last stage or at simulation.duration, whichever comes first."
        ),
    )
    output: Output = Field(default_factory=Output)

    @model_validator(mode="before")
    @classmethod
    def _default_tags(cls, data):
        return _fluid_only_defaults(_default_tag(data, "contact", "model", "linear"))

    @property
    def has_particles(self) -> bool:
        """False for a fluid-only scene (no [particles], or count = 0)."""
        return self.particles.count != 0


def _fluid_only_defaults(data):
    """A fluid-only scene (a [fluid], and no [particles] or count = 0) writes no per-particle
    fields and measures no particle observables unless the case lists some (then refused by
    consistency.py): the defaults of output.fields and output.observables.quantities are empty."""
    if not isinstance(data, dict) or data.get("fluid") is None:
        return data
    particles = data.get("particles")
    count = particles.get("count") if isinstance(particles, dict) else None
    if "particles" in data and not (type(count) is int and count == 0):
        return data
    output = data.get("output", {})
    if not isinstance(output, dict):
        return data
    output = {"fields": [], **output}
    observables = output.get("observables", {})
    if isinstance(observables, dict):
        output["observables"] = {"quantities": [], **observables}
    return {**data, "output": output}


# Keys whose change does not alter the physics of a run (resume accepts them changed).
NON_PHYSICS_KEYS = (
    ("title",),
    ("simulation", "duration"),
    ("simulation", "threads"),
    ("simulation", "neighbor_skin"),
    ("simulation", "device"),
    ("simulation", "rank_balance"),
    ("fluid", "solver", "rank_split_cells"),
    ("output",),
)
