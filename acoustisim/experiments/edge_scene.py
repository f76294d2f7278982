"""The range and angle sweeps' scene: the thesis tank with one steel prism, and the sonar placed at a position.

Scene: the 9 m x 3 m x 1 m concrete tank of fresh water with one steel prism whose sharp
60-degree vertical edge (the seed's "sharp edge of a triangle", a point target in the
horizontal plane) faces the sonar at ``EDGE_M``. The prism is ``PRISM_SIZE_M`` deep, so its two
rear edges (which diffract more strongly than the front one, being seen near grazing) lie
about 0.43 m behind the front edge, outside the range gate.

A position (``position_setup``): the sonar placed so that the edge is at a given range and
bearing, the head turned so that the line to the edge stays on the prism's bisector
(``geometry.pose_for_target`` with yaw = bearing); the record kept over the edge's range +/-
``GATE_HALF_WIDTH_M`` (blanking the main bang and the cross-talk); the truth the least-time TOF
from the transmitter to the edge's point at the head's height and back to each receiver.

Physics (the prism's faces)
---------------------------
Machined steel: its Lambert strength follows from first-order small-perturbation (Rayleigh-Rice)
backscatter of a rigid (Neumann) surface, the limit for steel in water (impedance ratio about
31), per unit area and solid angle: sigma = k^4 (1 + sin^2 t)^2 W(2 k sin t), t the incidence
angle from the normal and W the roughness's 2-D spectrum (Thorsos and Jackson 1989 give the
Dirichlet form 4 k^4 cos^4 t W; the Neumann factor follows from the same boundary
perturbation). For a Gaussian correlation of rms h and length L, W(K) = h^2 L^2 / (4 pi)
exp(-K^2 L^2 / 4), largest at L = 2 / K: W <= h^2 / (pi e K^2). The Lambert law
sigma = mu sin(g_i) sin(g_s) = mu cos^2 t in backscatter then gives mu.

Method: the closed form above at the prism's incidence (``small_roughness_lambert_mu``); the
library's "steel-machined" holds its value (``prism_material``), so the recording's truth scene
names a library material.

Accuracy: first order in k h (k h = 0.006 for 3 um at 500 kHz: the second-order terms are
~4e-5 relative); the upper bound over correlation lengths makes mu an upper bound too.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from acoustisim.experiments.gating import range_window_s
from acoustisim.experiments.geometry import pose_for_target
from acoustisim.experiments.truth import object_truth
from acoustisim.scene import Scene, Tank

EDGE_M: tuple[float, float] = (6.0, 1.5)
"""Tank-frame (x, y) of the prism's sharp edge (m): 6 m from the near wall, mid-width."""
PRISM_SIZE_M = 0.5
"""Depth of the prism (m): its rear edges are 0.43 m behind the front edge."""
PRISM_ANGLE_DEG = 60.0
"""Interior angle of the prism at its sharp edge (deg)."""
PRISM_RMS_ROUGHNESS_M = 3e-6
"""RMS roughness of the prism's faces (m): machined or cold-rolled steel plate (Ra 0.8-3.2 um,
rms about 1.25 Ra)."""
PRISM_MATERIAL = "steel-machined"
"""The prism's library material: steel with the Lambert strength of ``PRISM_RMS_ROUGHNESS_M`` at
500 kHz and 60 deg incidence (``acoustisim.materials``' docstring gives the derivation)."""
GATE_HALF_WIDTH_M = 0.1
"""Half depth of the range gate around the edge (m): +/-135 us, many envelope widths, and short of
the prism's rear edges (0.43 m behind). With the head on the tank's centre line at mid-depth, the
floor and surface (0.5 m away) and the side walls (1.5 m) still fall inside it at ranges within
0.1 m of theirs; a wider gate (0.2 m) let them in over twice those spans."""
TEMPLATE_S = 20e-6
"""The record runs this long (a template length) past the gate, so the last echo is whole (s)."""
SWEEP_MAX_ORDER = 4
"""Most reflections per specular path in the sweeps: the engine's maximum
(``acoustisim.propagation.paths.MAX_INTERACTIONS``). In a tank of depth H = 1 m the head's
vertical multiples (floor and surface, 90 deg off every axis) return at ranges k H / 2 for a head
at mid-depth and at k H for any depth: the floor-surface pair (order 2) at 1.0 m, order 3 at
1.5 m, order 4 at 2.0 m. Order 5, which returns at 2.5 m, is not modelled."""
NOISE_FREE_PARTS: tuple[str, ...] = ("edge", "specular", "all")
"""Noise-free records of a position: the edge's diffraction alone; plus the direct and specular
paths (walls, floor, surface); everything (plus the diffuse reverberation)."""


def small_roughness_lambert_mu(rms_roughness_m: float, frequency_hz: float, sound_speed_m_s: float,
                               incidence_deg: float) -> float:
    """Lambert strength equivalent to a slightly rough hard face's backscatter (upper bound over correlation lengths).

    The module notes' closed form, valid for k h << 1.

    Parameters
    ----------
    rms_roughness_m : float
        RMS height h (m).
    frequency_hz, sound_speed_m_s : float
        The wavenumber k = 2 pi f / c.
    incidence_deg : float
        Incidence angle from the face's normal (deg), in (0, 90).

    Returns
    -------
    float
        The Lambert strength mu that gives the same backscatter at that angle.
    """
    k = 2.0 * math.pi * frequency_hz / sound_speed_m_s
    t = math.radians(incidence_deg)
    if not (0.0 < t < 0.5 * math.pi and rms_roughness_m >= 0.0):
        raise ValueError(f"need 0 < incidence < 90 deg and h >= 0, got {incidence_deg!r}, {rms_roughness_m!r}")
    big_k = 2.0 * k * math.sin(t)
    w_max = rms_roughness_m ** 2 / (math.pi * math.e * big_k ** 2)
    sigma = k ** 4 * (1.0 + math.sin(t) ** 2) ** 2 * w_max
    return sigma / math.cos(t) ** 2


def prism_material() -> Any:
    """The library's machined steel ("steel-machined"), the prism's material.

    Its ``diffuse_mu`` is ``small_roughness_lambert_mu(PRISM_RMS_ROUGHNESS_M, 500 kHz, 1482 m/s,
    60 deg)`` to 3 significant digits: the faces of a prism seen along its bisector are at
    90 - angle / 2 deg from the line of sight (incidence 60 deg for the 60-degree prism).
    """
    from acoustisim.materials import get_material

    return get_material(PRISM_MATERIAL)


def edge_tank_scene(prism: Any = None) -> Scene:
    """The thesis tank with only the 60-degree prism facing -x (toward the sonar).

    Parameters
    ----------
    prism : Material or str, optional
        The prism's material; default ``prism_material()`` (machined steel). With a library
        material, ``simulate`` writes the scene into a recording's truth (a scene file names
        library materials only).
    """
    from acoustisim.medium import Medium
    from scenes.builders import default_sonar, edge_prism

    tank = Tank(length_m=9.0, width_m=3.0, water_depth_m=1.0, wall_material="concrete", floor_material="concrete")
    edge = edge_prism("edge", EDGE_M, PRISM_ANGLE_DEG, 180.0, PRISM_SIZE_M, tank.water_depth_m,
                      prism_material() if prism is None else prism)
    medium = Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5)
    return Scene(name="edge-tank", medium=medium, sonar=default_sonar(), tank=tank, objects=(edge,))


class Position(NamedTuple):
    """One position of a sweep (``position_setup``).

    Attributes
    ----------
    scene : Scene
        ``edge_tank_scene()`` (machined-steel prism): for propagation and for ``simulate``.
    sonar : SonarHead
        Placed with the edge at the position's range and bearing, seen along the prism's bisector;
        its record ends a template length after the gate.
    truth : ObjectTruth
    truth_tof_s : list of 3 float
        Least-time TOF (s) transmitter -> edge point at the head's height -> each receiver.
    gate : (start_s, stop_s)
        The kept part of the record (s after the trigger), a template length past the range gate.
    """

    scene: Scene
    sonar: Any
    truth: Any
    truth_tof_s: list[float]
    gate: tuple[float, float]

    @property
    def sound_speed_m_s(self) -> float:
        """The medium's sound speed (m/s)."""
        return float(self.scene.medium.sound_speed)

    @property
    def range_gate_s(self) -> tuple[float, float]:
        """The range gate itself (s after the trigger), without the template's length past it."""
        return self.gate[0], self.gate[1] - TEMPLATE_S


def position_setup(range_m: float, bearing_deg: float) -> Position:
    """The scene, the posed sonar, the edge's truth, its true TOFs and the gate of a position."""
    from dataclasses import replace

    scene = edge_tank_scene()
    c = float(scene.medium.sound_speed)
    start_s, stop_s = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    sonar = pose_for_target(scene.sonar, (*EDGE_M, scene.sonar.position_m[2]), range_m, bearing_deg,
                            yaw_deg=bearing_deg)
    sonar = replace(sonar, record_length_s=stop_s + TEMPLATE_S)
    truth = object_truth(scene, sonar, scene.objects[0])
    tx, rx = sonar.transmitter_position, sonar.receiver_positions
    truth_tof = [(float(np.linalg.norm(truth.position_tank_m - tx)) + float(np.linalg.norm(truth.position_tank_m - r)))
                 / c for r in rx]
    return Position(scene, sonar, truth, truth_tof, (start_s, stop_s + TEMPLATE_S))


def solver_config(params: dict[str, Any]) -> Any:
    """Propagation settings of a trial: ``max_order`` (default ``SWEEP_MAX_ORDER``), no amplitude
    floor, the diffuse tracer's ``diffuse_seed`` (default 0) and, with ``reverberation`` False,
    no diffuse mechanism (no Lambert reverberation from the floor, surface, walls and the prism's
    faces)."""
    from acoustisim.propagation import SolverConfig
    from acoustisim.propagation.config import MECHANISMS

    mechanisms = MECHANISMS if params.get("reverberation", True) else tuple(m for m in MECHANISMS if m != "diffuse")
    # No amplitude floor: the floor is judged at 500 kHz, where the pistons' directivity has its
    # first null at 11 deg; the broadband edge echo there (carried by 300-400 kHz) is 90 dB below the
    # walls' specular echoes and would be dropped, leaving only other returns in the gate.
    return SolverConfig(max_order=int(params.get("max_order", SWEEP_MAX_ORDER)), mechanisms=mechanisms,
                        amplitude_floor_db=None, seed=int(params.get("diffuse_seed", 0)))


def path_subsets(paths: Any) -> dict[str, Any]:
    """The ``NOISE_FREE_PARTS`` as row masks of ``paths`` (cumulative: each adds mechanisms)."""
    from acoustisim.propagation.paths import PathKind

    kind = paths.rows["kind"]
    edge = kind == PathKind.EDGE
    return {"edge": edge, "specular": kind != PathKind.DIFFUSE, "all": np.ones(kind.shape, dtype=bool)}
