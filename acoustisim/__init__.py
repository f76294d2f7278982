"""acoustisim: physics-based acoustic ray tracing and waveform synthesis for a wide-band
binaural sonar (500 kHz, three channels, 12-bit ADC).

Descriptions (frozen dataclasses): :class:`Medium`, :class:`Material`, :class:`SonarHead`,
:class:`Scene`, :class:`SceneObject`, :class:`Tank`. Solvers and results live in
``acoustisim.propagation`` and ``acoustisim.synthesis``.
"""

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, PlanePrimitive, SpherePrimitive
from acoustisim.materials import Material, get_material, material_library
from acoustisim.medium import Medium
from acoustisim.pulse import GaussianPulse, SampledPulse
from acoustisim.scene import Boundary, Scene, SceneObject, Tank
from acoustisim.sonar import CHANNEL_NAMES, SonarHead, Transducer

__version__ = "0.1.0"

__all__ = [
    "CHANNEL_NAMES",
    "Boundary",
    "CylinderPrimitive",
    "GaussianPulse",
    "InputError",
    "Material",
    "Medium",
    "PlanePrimitive",
    "SampledPulse",
    "Scene",
    "SceneObject",
    "SonarHead",
    "SpherePrimitive",
    "Tank",
    "Transducer",
    "get_material",
    "material_library",
]
