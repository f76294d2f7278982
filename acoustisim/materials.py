"""Materials: what a surface does to an incident wave.

Reflection models
-----------------
``elastic``
    Plane wave in the water on an elastic solid half-space (the default of the built-in solids),
    in the form of Brekhovskikh (*Waves in Layered Media*, 2nd ed., 1980, section 4;
    Brekhovskikh & Lysanov, *Fundamentals of Ocean Acoustics*, section 4.2; Jensen et al.,
    *Computational Ocean Acoustics*, 2nd ed., 2011, section 1.6):

        R = (Z_L cos^2 2t_S + Z_S sin^2 2t_S - Z_w) / (Z_L cos^2 2t_S + Z_S sin^2 2t_S + Z_w),

    Z_w = rho_w c_w / cos t, Z_L = rho c_L / cos t_L, Z_S = rho c_S / cos t_S, with Snell's law
    sin t_L / c_L = sin t_S / c_S = sin t / c_w. The compressional and shear waves carry energy
    into the solid, so |R| < 1 between the critical angles; past the compressional critical angle
    (c_L > c_w) cos t_L is imaginary, past the shear one (c_S > c_w: metals, glass, concrete)
    cos t_S too, and a lossless solid reflects totally with a phase that turns by 2 pi through
    the leaky Rayleigh angle (sin t_R = c_w / c_R); with losses |R| dips there. Losses enter
    through complex speeds, c~ = c / (1 + i eta / 2), so that k = (w / c)(1 + i eta / 2) with
    time dependence exp(-i w t). Method: the formula multiplied through by a_L cos t / (rho_w c_w),
    written with the refraction indices n = c_w / c~ (complex), a_L = sqrt(n_L^2 - sin^2 t) =
    n_L cos t_L, a_S = sqrt(n_S^2 - sin^2 t), m = rho / rho_w, x = sin^2 t / n_S^2 = sin^2 t_S:

        R = (m cos t G - a_L) / (m cos t G + a_L),  G = (1 - 2 x)^2 + 4 x a_S a_L / n_S^2,

    G being Rayleigh's function times c_S^4 (it vanishes at the Rayleigh slowness of the free
    solid, sin t = c_w / c_R, where R = -1 without losses). It has
    no division by a vanishing cosine at the critical angles; the root a of each square root is
    the one with Im(a) >= 0 (a wave that decays, or leaves, into the solid), Re(a) > 0 below the
    critical angle without losses. A fluid (c_S = 0) has G = 1: the ``fluid`` formula below, with
    the losses of c_L. Accuracy: rounding only (a few ulp of the complex arithmetic; the tests
    check it against the 3 x 3 boundary-condition system solved numerically, and against energy
    conservation). ``Material.is_solid`` tells whether a material has shear.
``fluid``
    Plane-wave fluid-fluid reflection R = (Z2 cos t1 - Z1 cos t2) / (Z2 cos t1 + Z1 cos t2),
    Z = rho c, Snell's law for t2; complex (total reflection with a phase) beyond the critical
    angle; lossless (the loss factors are not used). Shear waves are ignored, which overstates
    oblique |R| of a solid (|R| = 1 past the compressional critical angle, where between 40 and
    80 deg an elastic PVC face reflects -3 to -13 dB and concrete -1 to -12 dB): kept for fluids
    (sand) and for comparisons.
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

Elastic parameters and losses
-----------------------------
Every material also carries what the exact elastic scattering of :mod:`acoustisim.scattering`
needs: the shear speed c_S (0 for a fluid) and the loss factors eta_L, eta_S of compressional
and shear waves. With time dependence exp(-i w t) a wave of speed c and loss factor eta has the
wavenumber k = (w / c)(1 + i eta / 2) (structural-acoustics convention, ``conventions.md``); the
attenuation is alpha = eta w / (2 c) Np/m, i.e. eta = alpha c / (pi f) (constant over the band:
attenuation proportional to frequency). ``roughness_rms_m`` is the rms height h of the face, for
the coherent-reflection (Kirchhoff / Eckart) factor of :mod:`acoustisim.scattering.roughness`:
every specular reflection on the face loses exp(-2 (k h sin g)^2) of its pressure
(:mod:`acoustisim.propagation.roughness`) and the diffuse tracer scatters the lost energy on top
of the face's own mu (:mod:`acoustisim.propagation.reference.diffuse`).

Roughness defaults: 0 for every built-in material. The sources cited here give no surface
heights, neither for the tank's concrete nor for its objects. The only heights this module
derives are those behind the Lambert strengths (steel's mu = 0.002 is about 31 um rms, the
machined finish 3 um; by the same relation, mu proportional to h^2, concrete's 0.01 would be
at least 68 um and PVC's 0.003 at least 37 um): a roughness on the scale of the wavelength whose
scattered energy ``diffuse_mu`` already carries. Giving that roughness to ``roughness_rms_m``
too would count its energy twice in the diffuse part, for a coherent loss that would be small
anyway (68 um at 500 kHz: 0.36 dB per reflection at normal incidence, 0.09 dB at 30 deg). A
long-correlation roughness such as a 0.5 mm rms floor (4.9 dB per reflection at 30 deg
grazing, 19.5 dB at normal incidence) changes the tank's echoes a lot and is a
property of one tank that no cited source measures: a scene file sets it
(``[[materials]]`` with ``roughness_rms_m``, and ``diffuse_mu`` for the scattering on top).

Sources of the built-in elastic values (rho kg/m^3, c_L / c_S m/s) are the handbook values of
``physics.md`` section 3 (PVC 1380, 2380/1060; concrete 2300, 4000/2300; glass 2500,
5800/3400; steel 7850, 5900/3200), which agree with the standard tables to a few per cent
(Kaye & Laby, *Tables of Physical and Chemical Constants*, section 2.4.1; Selfridge, IEEE Trans.
Sonics Ultrason. SU-32, 381, 1985: mild steel 7850, 5960/3235; aluminium 2700, 6420/3040;
crown glass 2500, 5660/3420); aluminium keeps the library's 2700, 6320/3130 (rolled
aluminium alloy, the same tables). Loss factors are representative values, not measurements of
the tank's own objects: rigid PVC (unplasticised) eta_L = 0.03, eta_S = 0.05, within the range Ono (Appl. Sci. 10, 5265, 2020) measured for engineering
polymers at 0.5-5 MHz (damping factors alpha lambda / pi = eta of 0.01-0.065, shear above
compressional); metals and glass eta of 1e-3 to 4e-3 (the bottom of that range, Ono 2020, and
Ono, Appl. Sci. 12, 13026, 2022 for glasses); concrete (and mortar) eta_L = 0.05, eta_S = 0.08,
dominated by scattering from the aggregate at these frequencies (Ono 2022 measured mortars at
the top of the range). A scene file can override every value (``[[materials]]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError

ReflectionModel = Literal["elastic", "fluid", "rigid", "pressure-release", "fixed"]

REFLECTION_MODELS: tuple[str, ...] = ("elastic", "fluid", "rigid", "pressure-release", "fixed")
"""The reflection models (module docstring), as scene files name them."""


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
        Longitudinal (compressional) sound speed c_L (m/s); also ``compressional_speed_m_s``.
    shear_speed_m_s : float
        Shear speed c_S (m/s), 0 for a fluid; the plane-wave ``fluid`` reflection model ignores
        it, the ``elastic`` one and the elastic scattering of :mod:`acoustisim.scattering` use it.
    model : {"elastic", "fluid", "rigid", "pressure-release", "fixed"}
        Reflection model (see module docstring). The built-in solids use ``elastic``; the default
        ``fluid`` keeps a material built without naming its model as it was.
    fixed_reflection : float
        The coefficient of the ``fixed`` model.
    diffuse_mu : float
        Lambert scattering strength mu (dimensionless, 0 <= mu <= 1/pi).
    compressional_loss_factor, shear_loss_factor : float
        Loss factors eta_L, eta_S (dimensionless, >= 0): k = (w / c)(1 + i eta / 2).
    roughness_rms_m : float
        Rms height h of the surface (m, >= 0) for the coherent-reflection factor.
    """

    name: str
    density_kg_m3: float
    sound_speed_m_s: float
    shear_speed_m_s: float = 0.0
    model: ReflectionModel = "fluid"
    fixed_reflection: float = 0.0
    diffuse_mu: float = 0.0
    compressional_loss_factor: float = 0.0
    shear_loss_factor: float = 0.0
    roughness_rms_m: float = 0.0

    def __post_init__(self) -> None:
        if self.model not in REFLECTION_MODELS:
            raise InputError(f"material {self.name!r}: unknown reflection model {self.model!r} "
                             f"(known: {', '.join(REFLECTION_MODELS)})")
        for field in ("density_kg_m3", "sound_speed_m_s"):
            value = getattr(self, field)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"material {self.name!r}: {field} must be > 0, got {value!r}")
        for field in ("shear_speed_m_s", "compressional_loss_factor", "shear_loss_factor", "roughness_rms_m"):
            value = getattr(self, field)
            if not (math.isfinite(value) and value >= 0.0):
                raise InputError(f"material {self.name!r}: {field} must be finite and >= 0, got {value!r}")
        for field in ("compressional_loss_factor", "shear_loss_factor"):
            if getattr(self, field) >= 2.0:
                raise InputError(f"material {self.name!r}: {field} must be < 2 (k = (w/c)(1 + i eta/2)), "
                                 f"got {getattr(self, field)!r}")
        # Positive bulk modulus K = rho (c_L^2 - 4 c_S^2 / 3) > 0 (a stable solid).
        if not self.shear_speed_m_s < 0.5 * math.sqrt(3.0) * self.sound_speed_m_s:
            raise InputError(f"material {self.name!r}: shear_speed_m_s = {self.shear_speed_m_s!r} must be below "
                             f"sqrt(3)/2 of the compressional speed {self.sound_speed_m_s!r} (positive bulk modulus)")
        if not 0.0 <= self.diffuse_mu <= 1.0 / math.pi + 1e-12:
            raise InputError(f"material {self.name!r}: diffuse_mu must lie in [0, 1/pi], got {self.diffuse_mu!r}")
        if not -1.0 <= self.fixed_reflection <= 1.0:
            raise InputError(
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
        if self.model == "elastic":
            return self._elastic_reflection(cos1, medium_density_kg_m3, medium_sound_speed_m_s)
        z1 = medium_density_kg_m3 * medium_sound_speed_m_s
        z2 = self.density_kg_m3 * self.sound_speed_m_s
        sin1_sq = 1.0 - cos1 * cos1
        ratio = self.sound_speed_m_s / medium_sound_speed_m_s
        # cos t2 = sqrt(1 - (c2/c1)^2 sin^2 t1); imaginary (evanescent) beyond the critical angle,
        # with the branch Im(cos t2) >= 0 giving |R| = 1.
        cos2 = np.sqrt((1.0 - ratio * ratio * sin1_sq).astype(complex))
        return (z2 * cos1 - z1 * cos2) / (z2 * cos1 + z1 * cos2)

    def _elastic_reflection(self, cos1: NDArray[np.float64], medium_density_kg_m3: float,
                            medium_sound_speed_m_s: float) -> NDArray[np.complex128]:
        """The ``elastic`` model (module docstring) at incidence cosines ``cos1`` (in [0, 1]).

        Written with x = sin^2 t / n_S^2 (= sin^2 t_S): G = (1 - 2 x)^2 + 4 x a_S a_L / n_S^2, in
        place where it can (the fast engine calls it once per material and solve).
        """
        sin_sq = 1.0 - cos1 * cos1
        n_l = self.refraction_index(medium_sound_speed_m_s, "compressional")
        a_l = upper_root(n_l * n_l - sin_sq)
        solid = (self.density_kg_m3 / medium_density_kg_m3) * cos1
        if self.shear_speed_m_s > 0.0:
            n_s = self.refraction_index(medium_sound_speed_m_s, "shear")
            inverse_sq = 1.0 / (n_s * n_s)
            a_s = upper_root(n_s * n_s - sin_sq)
            x = sin_sq * inverse_sq
            rayleigh = 1.0 - 2.0 * x
            rayleigh *= rayleigh
            x *= 4.0 * inverse_sq
            x *= a_s
            x *= a_l
            rayleigh += x
            solid = solid * rayleigh
        return (solid - a_l) / (solid + a_l)

    def refraction_index(self, medium_sound_speed_m_s: float, wave: Literal["compressional", "shear"]) -> complex:
        """n = c_w / c~ = (c_w / c)(1 + i eta / 2) of the compressional or shear wave (complex,
        Im >= 0: the wave's loss, time dependence exp(-i w t)).

        Raises
        ------
        InputError
            ``wave`` is "shear" and the material has none (c_S = 0).
        """
        if wave == "compressional":
            speed, eta = self.sound_speed_m_s, self.compressional_loss_factor
        elif self.shear_speed_m_s > 0.0:
            speed, eta = self.shear_speed_m_s, self.shear_loss_factor
        else:
            raise InputError(f"material {self.name!r} carries no shear wave (shear_speed_m_s = 0)")
        return complex(medium_sound_speed_m_s / speed, 0.5 * eta * medium_sound_speed_m_s / speed)

    def normal_reflection(self, medium_density_kg_m3: float, medium_sound_speed_m_s: float) -> float:
        """Real part of the reflection coefficient at normal incidence (the coefficient itself
        but for a lossy ``elastic`` material, whose small imaginary part it drops)."""
        return float(self.reflection_coefficient(1.0, medium_density_kg_m3, medium_sound_speed_m_s).real)


    @property
    def compressional_speed_m_s(self) -> float:
        """c_L (m/s): the scene file's name for ``sound_speed_m_s``."""
        return self.sound_speed_m_s

    @property
    def is_solid(self) -> bool:
        """Whether the material carries shear waves (c_S > 0)."""
        return self.shear_speed_m_s > 0.0


def upper_root(values: ArrayLike) -> NDArray[np.complex128]:
    """The square root with Im >= 0 of complex ``values`` (any shape): the vertical wavenumber of
    a wave that decays, or carries energy, away from the interface (time dependence exp(-i w t)).

    numpy's principal root has Re >= 0 but takes the sign of a zero imaginary part (sqrt(-4 - 0j)
    = -2j); the root is negated where its imaginary part is negative.
    """
    root = np.sqrt(np.asarray(values, dtype=complex))
    if root.ndim == 0:
        return -root if root.imag < 0.0 else root
    return np.negative(root, out=root, where=root.imag < 0.0)


def material_library() -> Mapping[str, Material]:
    """The built-in materials, by name (a read-only mapping, built fresh on each call).

    Elastic values and losses with their sources in the module docstring. The solids reflect by
    the ``elastic`` model; sand is a fluid; the pipes keep their ``fixed`` coefficients (the echo
    of a thin wall is dominated by its fill, which a half-space model cannot describe).
    """
    materials = (
        Material("concrete", 2300.0, 4000.0, 2300.0, "elastic", diffuse_mu=0.01,
                 compressional_loss_factor=0.05, shear_loss_factor=0.08),
        Material("glass", 2500.0, 5800.0, 3400.0, "elastic", diffuse_mu=0.001,
                 compressional_loss_factor=0.002, shear_loss_factor=0.003),
        Material("pvc", 1380.0, 2380.0, 1060.0, "elastic", diffuse_mu=0.003,
                 compressional_loss_factor=0.03, shear_loss_factor=0.05),
        Material("steel", 7850.0, 5900.0, 3200.0, "elastic", diffuse_mu=0.002,
                 compressional_loss_factor=0.002, shear_loss_factor=0.003),
        # Machined finish, rms 3 um: small-perturbation mu at 500 kHz, 60 deg, 1.93e-5 (module docstring).
        Material("steel-machined", 7850.0, 5900.0, 3200.0, "elastic", diffuse_mu=1.9338212442616098e-05,
                 compressional_loss_factor=0.002, shear_loss_factor=0.003),
        Material("aluminium", 2700.0, 6320.0, 3130.0, "elastic", diffuse_mu=0.002,
                 compressional_loss_factor=0.001, shear_loss_factor=0.002),
        # Soft rubber: heavily damped (loss factors of order 0.1-0.3 are typical of elastomers).
        Material("rubber", 1100.0, 1600.0, 50.0, "elastic", diffuse_mu=0.005,
                 compressional_loss_factor=0.1, shear_loss_factor=0.3),
        # Water-saturated sand as a fluid: Hamilton's attenuation about 0.5 dB/(m kHz) -> eta = 0.03.
        Material("sand", 1900.0, 1650.0, 0.0, "fluid", diffuse_mu=0.03, compressional_loss_factor=0.03),
        Material("pvc-pipe-air", 1380.0, 2380.0, 1060.0, "fixed", fixed_reflection=-0.9, diffuse_mu=0.003,
                 compressional_loss_factor=0.03, shear_loss_factor=0.05),
        Material("pvc-pipe-water", 1380.0, 2380.0, 1060.0, "fixed", fixed_reflection=0.35, diffuse_mu=0.003,
                 compressional_loss_factor=0.03, shear_loss_factor=0.05),
        Material("rigid", 1.0e6, 1.0e6, 0.0, "rigid"),
        Material("pressure-release", 1.2, 343.0, 0.0, "pressure-release"),
        Material("air", 1.2, 343.0, 0.0, "pressure-release"),
    )
    return MappingProxyType({m.name: m for m in materials})


def get_material(name: str, scene_materials: Sequence[Material] = ()) -> Material:
    """Look a material up by name: first among ``scene_materials`` (a scene file's own
    ``[[materials]]``), then in the built-in library.

    Raises
    ------
    InputError
        Unknown name; the message names it and the known ones.
    """
    for material in scene_materials:
        if material.name == name:
            return material
    library = material_library()
    try:
        return library[name]
    except (KeyError, TypeError):
        known = ", ".join(sorted({*library, *(m.name for m in scene_materials)}))
        raise InputError(f"unknown material {name!r} (known: {known})") from None
