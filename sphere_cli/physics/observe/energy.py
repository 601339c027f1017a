"""Observables of the particle system (on the output schedule only): kinetic, gravitational
and elastic energy, and contact counts (kernels/observe/energy.py)."""

from __future__ import annotations

from ...kernels.observe.energy import kinetic_energy, potential_energy

# name -> (unit, the group of output.observables.quantities that asks for it)
QUANTITIES = {
    "kinetic_energy": ("J", "energy"),
    "potential_energy": ("J", "energy"),
    "elastic_energy": ("J", "energy"),
    "total_energy": ("J", "energy"),
    "contacts": ("", "contacts"),
    "wall_contacts": ("", "contacts"),
}
UNITS = {name: unit for name, (unit, _) in QUANTITIES.items()}
GROUPS = {name: group for name, (_, group) in QUANTITIES.items()}


def observables(scene) -> dict[str, float]:
    state = scene.state
    p = state.particles
    kinetic = float(kinetic_energy(p.vel, p.angvel, p.mass, p.inertia))
    potential = float(potential_energy(p.pos, p.mass, state.box.body_acc))
    elastic, contacts = scene.contact.elastic_energy(state)
    wall_contacts = 0
    if scene.walls is not None:
        wall_elastic, wall_contacts = scene.walls.elastic_energy(state)
        elastic += wall_elastic
    return {
        "kinetic_energy": kinetic,
        "potential_energy": potential,
        "elastic_energy": elastic,
        "total_energy": kinetic + potential + elastic,
        "contacts": contacts,
        "wall_contacts": wall_contacts,
    }
