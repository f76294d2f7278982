"""What a scatterer is made of: the descriptions the modal series take.

Physics
-------
Time dependence exp(-i w t) throughout this package. A medium of speed c and loss factor eta
has the complex wavenumber k = (w / c)(1 + i eta / 2) (``conventions.md``), i.e. the complex
speed c~ = c / (1 + i eta / 2); the Lame moduli of a solid follow from the complex speeds,
mu = rho c~_S^2, lambda = rho c~_L^2 - 2 mu (Faran 1951; the loss factors are constant over the
band: attenuation proportional to frequency).

Bodies
------
:class:`Rigid` (normal displacement zero), :class:`PressureRelease` (pressure zero),
:class:`Elastic` (a homogeneous solid; ``shear_speed_m_s = 0`` makes it a fluid) and
:class:`Shell` (an elastic wall of given thickness around a fluid fill: a pipe). The host water is
a :class:`Fluid`. :func:`body_from_material` maps a library or scene-file material to a body.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError
from acoustisim.materials import Material

if TYPE_CHECKING:
    from acoustisim.medium import Medium

__all__ = ("AIR", "Body", "Elastic", "Fluid", "PIPE_FILLS", "PressureRelease", "Rigid", "Shell",
           "body_from_material", "complex_wavenumber", "pipe_fill")


def complex_wavenumber(omega: ArrayLike, speed_m_s: float, loss_factor: float) -> NDArray[np.complex128]:
    """k = (w / c)(1 + i eta / 2) (1/m), the shape of ``omega`` (rad/s)."""
    return np.asarray(omega, dtype=float) / speed_m_s * (1.0 + 0.5j * loss_factor)


class Fluid(NamedTuple):
    """A fluid: the host water or a pipe's fill.

    Attributes
    ----------
    density_kg_m3 : float
    sound_speed_m_s : float
    loss_factor : float
        eta (0 for the host water: the simulator applies the water's absorption per path).
    """

    density_kg_m3: float
    sound_speed_m_s: float
    loss_factor: float = 0.0

    def wavenumber(self, omega: ArrayLike) -> NDArray[np.complex128]:
        """k (1/m), shape of ``omega``."""
        return complex_wavenumber(omega, self.sound_speed_m_s, self.loss_factor)

    @classmethod
    def from_medium(cls, medium: "Medium") -> "Fluid":
        """The host water of a scene's :class:`acoustisim.medium.Medium` (loss 0: the simulator
        applies the water's absorption per path)."""
        return cls(float(medium.density), float(medium.sound_speed))


AIR = Fluid(1.204, 343.2, 1.0e-3)
"""Air at 20 C and 1 atm filling a pipe: density 1.204 kg/m^3, speed 343.2 m/s (Kaye & Laby 2.4.1),
loss factor eta = alpha c / (pi f) = 1.0e-3 from the classical and rotational absorption of
ISO 9613-1 (1993), alpha = 1.84e-11 f^2 Np/m, at the sonar's 500 kHz (alpha grows as f^2, eta as
f: 2e-4 at 100 kHz, 2e-3 at 1 MHz; the constant value is the band centre's). Without it the
lossless air column of an infinite pipe rings for milliseconds at -50 dB of the echo, which
no capped 0.6 m pipe of real air does."""

PIPE_FILLS: tuple[str, ...] = ("air", "water")
"""What a pipe may be filled with (the scene file's ``fill``)."""


def pipe_fill(name: str, water: Fluid) -> Fluid:
    """The fill called ``name``: :data:`AIR`, or the host ``water`` itself.

    Raises
    ------
    InputError
        An unknown name (the known ones are :data:`PIPE_FILLS`).
    """
    if name == "air":
        return AIR
    if name == "water":
        return water
    raise InputError(f"fill = {name!r}: expected one of {', '.join(map(repr, PIPE_FILLS))}")


@dataclass(frozen=True)
class Rigid:
    """Immovable surface: normal displacement zero (R = +1)."""


@dataclass(frozen=True)
class PressureRelease:
    """Soft surface: pressure zero (R = -1)."""


@dataclass(frozen=True)
class Elastic:
    """A homogeneous isotropic solid (a fluid when ``shear_speed_m_s`` is 0).

    Attributes
    ----------
    density_kg_m3 : float
    compressional_speed_m_s, shear_speed_m_s : float
        c_L, c_S (m/s); c_S = 0 for a fluid.
    compressional_loss_factor, shear_loss_factor : float
        eta_L, eta_S.
    """

    density_kg_m3: float
    compressional_speed_m_s: float
    shear_speed_m_s: float = 0.0
    compressional_loss_factor: float = 0.0
    shear_loss_factor: float = 0.0

    def __post_init__(self) -> None:
        if not (self.density_kg_m3 > 0.0 and self.compressional_speed_m_s > 0.0 and self.shear_speed_m_s >= 0.0):
            raise InputError(f"elastic body: density and speeds must be positive, got {self!r}")

    @property
    def is_fluid(self) -> bool:
        """No shear waves."""
        return self.shear_speed_m_s == 0.0

    def compressional_wavenumber(self, omega: ArrayLike) -> NDArray[np.complex128]:
        """k_L (1/m), shape of ``omega``."""
        return complex_wavenumber(omega, self.compressional_speed_m_s, self.compressional_loss_factor)

    def shear_wavenumber(self, omega: ArrayLike) -> NDArray[np.complex128]:
        """k_T (1/m), shape of ``omega`` (only for a solid)."""
        return complex_wavenumber(omega, self.shear_speed_m_s, self.shear_loss_factor)

    def lame_moduli(self) -> tuple[complex, complex]:
        """(lambda, mu) (Pa), complex: mu = rho c~_S^2, lambda = rho c~_L^2 - 2 mu."""
        c_l = self.compressional_speed_m_s / (1.0 + 0.5j * self.compressional_loss_factor)
        c_s = self.shear_speed_m_s / (1.0 + 0.5j * self.shear_loss_factor)
        mu = self.density_kg_m3 * c_s * c_s
        return self.density_kg_m3 * c_l * c_l - 2.0 * mu, mu


@dataclass(frozen=True)
class Shell:
    """A cylindrical elastic wall around a fluid fill (a pipe): outer radius from the object,
    ``thickness_m`` inwards.

    Attributes
    ----------
    wall : Elastic
        The wall's material (a solid).
    thickness_m : float
        h (m), 0 < h < outer radius.
    fill : Fluid
        What fills the pipe (water or air).
    """

    wall: Elastic
    thickness_m: float
    fill: Fluid

    def __post_init__(self) -> None:
        if self.wall.is_fluid:
            raise InputError("shell: the wall must be a solid (shear_speed_m_s > 0)")
        if not self.thickness_m > 0.0:
            raise InputError(f"shell: thickness_m = {self.thickness_m!r}: must be > 0")


Body = Union[Rigid, PressureRelease, Elastic, Shell]


def elastic_from_material(material: Material) -> Elastic:
    """The material's elastic parameters as a body (whatever its plane-wave reflection model)."""
    return Elastic(material.density_kg_m3, material.sound_speed_m_s, material.shear_speed_m_s,
                   material.compressional_loss_factor, material.shear_loss_factor)


def body_from_material(material: Material, *, wall_thickness_m: float | None = None,
                       fill: Fluid | None = None) -> Body:
    """The body a material makes: rigid and pressure-release models map to those limits, every
    other material to its elastic solid (or fluid), or to a :class:`Shell` when a wall
    thickness and fill are given.

    Raises
    ------
    InputError
        A ``fixed``-coefficient material without a wall thickness: a fixed plane-wave coefficient
        describes no body (describe the pipe as a shell instead); or only one of
        ``wall_thickness_m`` and ``fill``.
    """
    if (wall_thickness_m is None) != (fill is None):
        raise InputError(f"material {material.name!r}: a shell needs both wall_thickness_m and fill")
    if material.model == "rigid":
        return Rigid()
    if material.model == "pressure-release":
        return PressureRelease()
    if wall_thickness_m is not None and fill is not None:
        return Shell(elastic_from_material(material), float(wall_thickness_m), fill)
    if material.model == "fixed":
        raise InputError(f"material {material.name!r}: a fixed reflection coefficient describes no scattering "
                         "body; give the pipe's wall thickness and fill (a Shell)")
    return elastic_from_material(material)
