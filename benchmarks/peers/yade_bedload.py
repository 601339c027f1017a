# YADE script of configs/bedload-yade.toml (run by bedload_compare.py with Debian's yade:
# `yade -n -x -j1 yade_bedload.py BED.csv SECONDS`): the scene of YADE's two-way coupled bedload
# example (HydroForceEngine with its 1D RANS fluid resolution), set up as that example does, but
# starting from sphere's deposited bed so that both codes advance the same spheres. Prints the
# wall time per simulated second of the coupled flow, after the initial 1 s fluid resolution.
import math
import sys
import time

import numpy as np
from yade import O, utils
from yade.wrapper import (
    Bo1_Box_Aabb,
    Bo1_Sphere_Aabb,
    ForceResetter,
    GlobalStiffnessTimeStepper,
    HydroForceEngine,
    Ig2_Box_Sphere_ScGeom,
    Ig2_Sphere_Sphere_ScGeom,
    InsertionSortCollider,
    InteractionLoop,
    Ip2_ViscElMat_ViscElMat_ViscElPhys,
    Law2_ScGeom_ViscElPhys_Basic,
    NewtonIntegrator,
    PyRunner,
    ViscElMat,
)

bed_file, seconds = sys.argv[1], float(sys.argv[2])
d, rho_p, rho_f, nu = 6e-3, 2500.0, 1000.0, 1e-6
slope, layers, phi_max = 0.05, 10, 0.61
fluid_height = 0.168  # the fluid bottom at z = 0 and 17.5 d of water over the 10 layers
cells, fluid_dt, fluid_period = 900, 1e-5, 1e-2
side = 10 * d
g = (9.81 * math.sin(slope), 0.0, -9.81 * math.cos(slope))
# the example's stiffness: its estimate of the bed's largest pressure times d times 1e4
stiffness = (rho_p - rho_f) * phi_max * layers * d * abs(g[2]) * d * 1e4
O.materials.append(
    ViscElMat(en=0.7, et=0.0, young=stiffness / d, poisson=0.5, density=rho_p, frictionAngle=math.atan(0.5))
)
O.periodic = True
O.cell.setBox(side, side, 5 * fluid_height)
O.bodies.append(utils.box(center=(side / 2, side / 2, d / 2), extents=(200, 200, 0), fixed=True))
bed = np.loadtxt(bed_file, delimiter=",", skiprows=1)
mobile = []
for x, y, z, r, fixed in bed:
    body = O.bodies.append(utils.sphere((x, y, z), r, fixed=bool(fixed)))
    if not fixed:
        mobile.append(body)
dz = fluid_height / (cells - 1)
hydro = HydroForceEngine(
    densFluid=rho_f,
    viscoDyn=nu * rho_f,
    zRef=0.0,
    gravity=g,
    deltaZ=dz,
    expoRZ=3.1,
    lift=False,
    nCell=cells,
    vCell=side * side * dz,
    radiusPart=d / 2,
    ids=mobile,
)


def fluid_model():
    hydro.averageProfile()
    hydro.fluidResolution(fluid_period, fluid_dt)


O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb()], allowBiggerThanPeriod=True),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom()],
        [Ip2_ViscElMat_ViscElMat_ViscElPhys()],
        [Law2_ScGeom_ViscElPhys_Basic()],
    ),
    hydro,
    PyRunner(command="fluid_model()", virtPeriod=fluid_period),
    GlobalStiffnessTimeStepper(defaultDt=1e-4, viscEl=True, timestepSafetyCoefficient=0.7),
    NewtonIntegrator(damping=0.0, gravity=g),
]
hydro.initialization()
hydro.ReynoldStresses = np.ones(cells) * 1e-4
hydro.turbulentFluctuation()
hydro.averageProfile()
hydro.fluidResolution(1.0, fluid_dt)
O.run(100, True)
kn = [i.phys.kn for i in O.interactions if i.isReal]
start, t0, n0 = time.perf_counter(), O.time, O.iter
while O.time - t0 < seconds:
    O.run(100, True)
wall = time.perf_counter() - start
steps = O.iter - n0
print(
    f"YADE: {wall / (O.time - t0):.3f} s per simulated second, {steps} steps, dt {O.dt:.4g} s, "
    f"{len(O.bodies) - 1} spheres, contact k_n {np.median(kn):.6g} N/m, "
    f"{steps * len(mobile) / wall / 1e6:.3f} M particle-steps/s"
)
