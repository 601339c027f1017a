"""The 1D vertical fluid column of `[fluid] model = "vans1d"` (kernels/vans1d.py): mesh, velocity
profile, mixing length and the implicit momentum solve.
"""

from __future__ import annotations

import numpy as np

from ..kernels.vans1d import MIXING_KINDS, advance_fluid, mixing_length, shear_stress
from .layer_averaging import layer_faces


class FluidColumn:
    """Velocity profile u at the centres of the layers `faces`, advanced with fixed solid
    profiles (phi, vel_p, beta); every array is allocated here, once."""

    def __init__(
        self,
        faces: np.ndarray,
        rho: float,
        nu: float,
        mixing: str = "none",
        kappa: float = 0.41,
        phi_max: float = 0.61,
        top_no_slip: bool = False,
    ):
        self.faces = np.ascontiguousarray(faces, dtype=np.float64)
        self.centres = 0.5 * (self.faces[1:] + self.faces[:-1])
        n = self.centres.size
        self.rho, self.nu = float(rho), float(nu)
        self.kind = MIXING_KINDS[mixing]
        self.kappa, self.phi_max = float(kappa), float(phi_max)
        self.top_no_slip = bool(top_no_slip)
        self.u = np.zeros(n)
        self.mixing = np.zeros(n + 1)
        self._coef = np.zeros(n + 1)
        self._scratch = tuple(np.zeros(n) for _ in range(5))

    @classmethod
    def regular(cls, bottom, top, cells, stretching=1.0, **kwargs) -> FluidColumn:
        return cls(layer_faces(bottom, top, cells, stretching), **kwargs)

    @property
    def cells(self) -> int:
        return self.centres.size

    def update_mixing_length(self, phi: np.ndarray) -> None:
        mixing_length(self.faces, phi, self.kind, self.kappa, self.phi_max, self.mixing)

    def advance(self, phi, vel_p, beta, source: float, dt: float, steps: int) -> None:
        """`steps` implicit steps of dt [s] with the solid profiles fixed; source = rho g_x - dp/dx
        [N/m^3]. The mixing length must be up to date with phi."""
        advance_fluid(
            self.faces, self.centres, self.u, phi, vel_p, beta, self.mixing, self.rho, self.nu,
            float(source), self.top_no_slip, float(dt), int(steps), self._coef, *self._scratch,
        )  # fmt: skip

    def shear_stress(self, phi: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Fluid shear stress at the n+1 faces [Pa] into `out`."""
        shear_stress(
            self.faces, self.centres, self.u, phi, self.mixing, self.rho, self.nu, self.top_no_slip, out
        )
        return out
