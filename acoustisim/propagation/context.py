"""What every propagation mechanism needs for one sonar pose: the solve context.

:func:`acoustisim.propagation.solve` builds one :class:`SolveContext` per call and hands it to
each mechanism (direct, specular, and the edge and diffuse modules), each of which returns an
array of ``PATH_DTYPE`` rows. Path ids of a mechanism start at ``first_path_id``; the solver
renumbers nothing, it passes each mechanism the next free id. Mechanisms fill the geometric
columns (ids, channel, kind, order, ``path_length_m``, ``geometric_gain``, ``phase_rad``,
directions, ``object_ids``, ``points_m``); the solver then fills the derived ones with
:meth:`~acoustisim.propagation.engine.Engine.assemble_rows`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Scene
from acoustisim.sonar import SonarHead


@dataclass(frozen=True, eq=False)
class SolveContext:
    """The scene, the pose and the shared ray caster for one solve.

    Attributes
    ----------
    scene : Scene
    sonar : SonarHead
        The pose being solved (may differ from ``scene.sonar``).
    raycaster : RayCaster
        Embree scene of ``scene`` (built once per scene, reused across poses).
    transmitter_m : ndarray, shape (3,)
        Transmitter face centre (tank frame, m).
    receivers_m : ndarray, shape (3, 3)
        Receiver face centres, rows left, centre, right (tank frame, m).
    boresight : ndarray, shape (3,)
        Unit acoustic axis of every transducer (tank frame).
    sound_speed_m_s : float
        c (m/s), for delays.
    density_kg_m3 : float
        Water density (kg/m^3), for reflection coefficients.
    centre_frequency_hz : float
        f0 (Hz), where directivity, absorption and amplitude columns are evaluated.
    absorption_db_per_m : float
        Absorption at f0 (dB/m).
    piston_radius_m : float
        Transducer radius a (m).
    first_path_id : int
        The first ``path_id`` the mechanism may use (ids are unique per physical path).
    """

    scene: Scene
    sonar: SonarHead
    raycaster: RayCaster
    transmitter_m: NDArray[np.float64] = field(repr=False)
    receivers_m: NDArray[np.float64] = field(repr=False)
    boresight: NDArray[np.float64] = field(repr=False)
    sound_speed_m_s: float
    density_kg_m3: float
    centre_frequency_hz: float
    absorption_db_per_m: float
    piston_radius_m: float
    first_path_id: int = 0

    @classmethod
    def build(cls, scene: Scene, sonar: SonarHead, raycaster: RayCaster, first_path_id: int = 0) -> "SolveContext":
        """The context of ``sonar``'s pose in ``scene``."""
        f0 = float(sonar.centre_frequency_hz)
        return cls(
            scene=scene,
            sonar=sonar,
            raycaster=raycaster,
            transmitter_m=np.asarray(sonar.transmitter_position, dtype=float),
            receivers_m=np.asarray(sonar.receiver_positions, dtype=float),
            boresight=np.asarray(sonar.boresight, dtype=float),
            sound_speed_m_s=float(scene.medium.sound_speed),
            density_kg_m3=float(scene.medium.density),
            centre_frequency_hz=f0,
            absorption_db_per_m=float(np.asarray(scene.medium.absorption_db_per_m(f0))),
            piston_radius_m=float(sonar.piston_radius_m),
            first_path_id=int(first_path_id),
        )

    def with_first_path_id(self, first_path_id: int) -> "SolveContext":
        """A copy whose mechanisms start numbering paths at ``first_path_id``."""
        return replace(self, first_path_id=int(first_path_id))


__all__ = ["SolveContext"]
