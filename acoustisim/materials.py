"""Materials: what a surface does to an incident wave.

Reflection models
-----------------
``fluid``
    Plane-wave fluid-fluid reflection R = (Z2 cos t1 - Z1 cos t2) / (Z2 cos t1 + Z1 cos t2),
    Z = rho c, Snell's law for t2; complex (total reflection with a phase) beyond the critical
    angle. Shear waves are ignored, which overstates oblique |R| for PVC and concrete.
``rigid``
    R = +1 at every angle (validation).
``pressure-release``
    R = -1 at every angle (the free surface, air; validation).
``fixed``
    A constant coefficient ``fixed_reflection`` at every angle: thin-walled pipes whose echo
    is dominated by what fills them (air-filled PVC pipe about -0.9, water-filled about +0.35
    for the front wall alone).

Each material also has a Lambert diffuse scattering strength ``diffuse_mu`` (<= 1/pi): the
fraction of the incident intensity scattered diffusely, used by the reverberation tracer.

Surface finish
--------------
``steel`` has mu = 0.002 (-27 dB), a rusted or sand-blasted face (rms roughness about 31 um).
``steel-machined`` is the same metal with a machined or cold-rolled finish (Ra 0.8-3.2 um, rms
h = 3 um): mu = 1.93e-5 (-47 dB), the first-order small-perturbation (Rayleigh-Rice) backscatter
of a rigid face, sigma = k^4 (1 + sin^2 t)^2 W(2 k sin t), with the Gaussian roughness spectrum
at its worst correlation length, W <= h^2 / (pi e (2 k sin t)^2), equated to the Lambert law
mu cos^2 t. Evaluated at 500 kHz in fresh water at 20 C (c = 1482 m/s, k = 2120 /m, k h = 0.0064)
and at t = 60 deg from the normal (the faces of a 60-degree prism seen along its bisector):
mu = 1.9338e-5. The library keeps the formula's double (``acoustisim.experiments.edge_scene.
small_roughness_lambert_mu``; ``tests/physics/test_materials.py`` recomputes it): the inputs justify about
one digit, but all digits make the figures of the sweeps that use it reproducible from the formula.
mu scales as h^2; the equivalent mu at other angles is about half at 30-45 deg, 3.7 times at 75 deg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

ReflectionModel = Literal["fluid", "rigid", "pressure-release", "fixed"]


@dataclass(frozen=True)
class Material:
    """An acoustic material.

    Attributes
    ----------
    name : str
        Key in the library (as written in scene files).
    density_kg_m3 : float
        Density (kg/m^3).
    sound_speed_m_s : float
        Longitudinal (compressional) sound speed (m/s).
    shear_speed_m_s : float
        Shear speed (m/s); informative, the fluid model ignores it.
    model : {"fluid", "rigid", "pressure-release", "fixed"}
        Reflection model (see module docstring).
    fixed_reflection : float
        The coefficient of the ``fixed`` model.
    diffuse_mu : float
        Lambert scattering strength mu (dimensionless, 0 <= mu <= 1/pi).
    """

    name: str
    density_kg_m3: float
    sound_speed_m_s: float
    shear_speed_m_s: float = 0.0
    model: ReflectionModel = "fluid"
    fixed_reflection: float = 0.0
    diffuse_mu: float = 0.0

    def __post_init__(self) -> None:
        if self.model not in ("fluid", "rigid", "pressure-release", "fixed"):
            raise ValueError(f"material {self.name!r}: unknown reflection model {self.model!r}")
        for field in ("density_kg_m3", "sound_speed_m_s"):
            value = getattr(self, field)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"material {self.name!r}: {field} must be > 0, got {value!r}")
        if not 0.0 <= self.diffuse_mu <= 1.0 / math.pi + 1e-12:
            raise ValueError(f"material {self.name!r}: diffuse_mu must lie in [0, 1/pi], got {self.diffuse_mu!r}")
        if not -1.0 <= self.fixed_reflection <= 1.0:
            raise ValueError(
                f"material {self.name!r}: fixed_reflection must lie in [-1, 1], got {self.fixed_reflection!r}"
            )

    def reflection_coefficient(
        self, cos_incidence: ArrayLike, medium_density_kg_m3: float, medium_sound_speed_m_s: float
    ) -> NDArray[np.complex128]:
        """Plane-wave pressure reflection coefficient.

        Parameters
        ----------
        cos_incidence : array_like, shape (n,) or scalar
            Cosine of the incidence angle from the surface normal, in [0, 1].
        medium_density_kg_m3, medium_sound_speed_m_s : float
            The water's density and sound speed.

        Returns
        -------
        ndarray of complex, same shape as ``cos_incidence``
        """
        cos1 = np.clip(np.asarray(cos_incidence, dtype=float), 0.0, 1.0)
        if self.model == "rigid":
            return np.ones_like(cos1, dtype=complex)
        if self.model == "pressure-release":
            return -np.ones_like(cos1, dtype=complex)
        if self.model == "fixed":
            return np.full_like(cos1, self.fixed_reflection, dtype=complex)
        z1 = medium_density_kg_m3 * medium_sound_speed_m_s
        z2 = self.density_kg_m3 * self.sound_speed_m_s
        sin1_sq = 1.0 - cos1 * cos1
        ratio = self.sound_speed_m_s / medium_sound_speed_m_s
        # cos t2 = sqrt(1 - (c2/c1)^2 sin^2 t1); imaginary (evanescent) beyond the critical angle,
        # with the branch Im(cos t2) >= 0 giving |R| = 1.
        cos2 = np.sqrt((1.0 - ratio * ratio * sin1_sq).astype(complex))
        return (z2 * cos1 - z1 * cos2) / (z2 * cos1 + z1 * cos2)

    def normal_reflection(self, medium_density_kg_m3: float, medium_sound_speed_m_s: float) -> float:
        """Real reflection coefficient at normal incidence."""
        return float(self.reflection_coefficient(1.0, medium_density_kg_m3, medium_sound_speed_m_s).real)


def material_library() -> Mapping[str, Material]:
    """The built-in materials, by name (a read-only mapping, built fresh on each call).

    Handbook values (rho kg/m^3, c_L / c_S m/s), see ``physics.md`` section 3.
    """
    materials = (
        Material("concrete", 2300.0, 4000.0, 2300.0, "fluid", diffuse_mu=0.01),
        Material("glass", 2500.0, 5800.0, 3400.0, "fluid", diffuse_mu=0.001),
        Material("pvc", 1380.0, 2380.0, 1060.0, "fluid", diffuse_mu=0.003),
        Material("steel", 7850.0, 5900.0, 3200.0, "fluid", diffuse_mu=0.002),
        # Machined finish, rms 3 um: small-perturbation mu at 500 kHz, 60 deg, 1.93e-5 (module docstring).
        Material("steel-machined", 7850.0, 5900.0, 3200.0, "fluid", diffuse_mu=1.9338212442616098e-05),
        Material("aluminium", 2700.0, 6320.0, 3130.0, "fluid", diffuse_mu=0.002),
        Material("rubber", 1100.0, 1600.0, 50.0, "fluid", diffuse_mu=0.005),
        Material("sand", 1900.0, 1650.0, 0.0, "fluid", diffuse_mu=0.03),
        Material("pvc-pipe-air", 1380.0, 2380.0, 1060.0, "fixed", fixed_reflection=-0.9, diffuse_mu=0.003),
        Material("pvc-pipe-water", 1380.0, 2380.0, 1060.0, "fixed", fixed_reflection=0.35, diffuse_mu=0.003),
        Material("rigid", 1.0e6, 1.0e6, 0.0, "rigid"),
        Material("pressure-release", 1.2, 343.0, 0.0, "pressure-release"),
        Material("air", 1.2, 343.0, 0.0, "pressure-release"),
    )
    return MappingProxyType({m.name: m for m in materials})


def get_material(name: str) -> Material:
    """Look a material up by name; raises ``KeyError`` naming the known ones."""
    library = material_library()
    try:
        return library[name]
    except KeyError:
        known = ", ".join(sorted(library))
        raise KeyError(f"unknown material {name!r} (known: {known})") from None
