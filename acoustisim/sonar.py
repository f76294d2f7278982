"""The sonar head: pose, three transducers, pulse and digitiser settings.

Frames (``conventions.md``): the head frame has its origin at the centre of the
transmitter's face, y forward along the boresight, x toward the right receiver, z up. The
pose places it in the tank frame: position of the head origin, then yaw (about +z, from the
tank +x axis to the boresight, counter-clockwise seen from above), pitch (about the head x
axis, positive nose up) and roll (about the boresight, positive right side down), applied
as R = Rz(yaw) R0 Rx(pitch) Ry(roll) with R0 the yaw-0 mapping head (x, y, z) -> tank
(-y, x, z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from acoustisim.pulse import GaussianPulse, SampledPulse

CHANNEL_NAMES: tuple[str, str, str] = ("left", "centre", "right")
TransducerRole = Literal["transmit-receive", "receive"]


@dataclass(frozen=True)
class Transducer:
    """One circular piston transducer.

    Attributes
    ----------
    name : str
        "left", "centre" or "right".
    role : {"transmit-receive", "receive"}
    position_head_m : tuple of 3 float
        Centre of the face in the head frame (m).
    axis_head : tuple of 3 float
        Unit vector of the acoustic axis in the head frame.
    radius_m : float
        Piston radius a (m).
    """

    name: str
    role: TransducerRole
    position_head_m: tuple[float, float, float]
    axis_head: tuple[float, float, float]
    radius_m: float


def _check_finite_positive(owner: str, name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{owner}.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class SonarHead:
    """The binaural sonar: a centre transmitter/receiver flanked by two receivers.

    Attributes
    ----------
    position_m : tuple of 3 float
        Head origin in the tank frame (m).
    yaw_deg, pitch_deg, roll_deg : float
        Orientation (degrees), see the module docstring.
    separation_m : float
        d, centre-to-side separation (m); left receiver at x = -d, right at x = +d.
    transducer_diameter_m : float
        Piston diameter 2a (m); the Panametrics V318 is 19 mm.
    centre_frequency_hz : float
        Pulse carrier f0 (Hz).
    pulse_duration_s : float
        Gaussian pulse duration T (s).
    source_level_pa : float
        Peak pressure of the pulse at 1 m on axis (Pa).
    sample_rate_hz : float
        Digitiser rate (Hz).
    adc_bits : int
        Digitiser resolution (bits).
    record_length_s : float
        Record length after the trigger (s).
    channel_positions_m : tuple of three 3-tuples, optional
        Overrides the (left, centre, right) positions in the head frame (m), e.g. for unequal
        offsets or receivers at different heights. The transmitter stays at the centre entry.
    custom_pulse : SampledPulse, optional
        A measured pulse or chirp replacing the Gaussian pulse.
    """

    position_m: tuple[float, float, float] = (1.0, 1.5, 0.5)
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    separation_m: float = 0.065
    transducer_diameter_m: float = 0.019
    centre_frequency_hz: float = 500e3
    pulse_duration_s: float = 5e-6
    source_level_pa: float = 1.0e5
    sample_rate_hz: float = 20e6
    adc_bits: int = 12
    record_length_s: float = 0.0125
    channel_positions_m: tuple[tuple[float, float, float], ...] | None = None
    custom_pulse: SampledPulse | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        position = tuple(float(v) for v in np.asarray(self.position_m, dtype=float).ravel())
        if len(position) != 3 or not all(math.isfinite(v) for v in position):
            raise ValueError(f"sonar.position_m must be 3 finite numbers, got {self.position_m!r}")
        object.__setattr__(self, "position_m", position)
        for name in ("yaw_deg", "pitch_deg", "roll_deg"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"sonar.{name} must be finite, got {value!r}")
        for name in (
            "separation_m",
            "transducer_diameter_m",
            "centre_frequency_hz",
            "pulse_duration_s",
            "source_level_pa",
            "sample_rate_hz",
            "record_length_s",
        ):
            _check_finite_positive("sonar", name, getattr(self, name))
        if not (isinstance(self.adc_bits, int) and 2 <= self.adc_bits <= 24):
            raise ValueError(f"sonar.adc_bits must be an integer in [2, 24], got {self.adc_bits!r}")
        if self.channel_positions_m is not None:
            positions = np.asarray(self.channel_positions_m, dtype=float)
            if positions.shape != (3, 3) or not np.all(np.isfinite(positions)):
                raise ValueError(
                    f"sonar.channel_positions_m must be 3 rows of 3 finite numbers, got {self.channel_positions_m!r}"
                )
            object.__setattr__(
                self, "channel_positions_m", tuple(tuple(float(v) for v in row) for row in positions)
            )

    # ----------------------------------------------------------------- geometry
    @property
    def piston_radius_m(self) -> float:
        """Piston radius a (m)."""
        return 0.5 * self.transducer_diameter_m

    @property
    def rotation(self) -> NDArray[np.float64]:
        """Rotation matrix (3, 3) taking head-frame vectors to the tank frame.

        One implementation of the convention serves the simulator and the pipeline (binsonar
        must not import the simulator, so it lives there).
        """
        from binsonar.localization.frames import head_to_tank_rotation

        return head_to_tank_rotation(self.yaw_deg, self.pitch_deg, self.roll_deg)

    @property
    def channel_positions_head(self) -> NDArray[np.float64]:
        """Transducer face centres (3, 3) in the head frame (m), rows left, centre, right."""
        if self.channel_positions_m is not None:
            return np.array(self.channel_positions_m, dtype=float)
        d = self.separation_m
        return np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]])

    @property
    def transducers(self) -> tuple[Transducer, Transducer, Transducer]:
        """The three transducers (left, centre, right); the centre one transmits."""
        rows = self.channel_positions_head
        roles: tuple[TransducerRole, ...] = ("receive", "transmit-receive", "receive")
        return tuple(  # type: ignore[return-value]
            Transducer(name, role, tuple(float(v) for v in row), (0.0, 1.0, 0.0), self.piston_radius_m)
            for name, role, row in zip(CHANNEL_NAMES, roles, rows)
        )

    def head_to_tank(self, points_head: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map points (n, 3) from the head frame to the tank frame (m)."""
        return np.asarray(points_head, dtype=float) @ self.rotation.T + np.asarray(self.position_m)

    def tank_to_head(self, points_tank: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map points (n, 3) from the tank frame to the head frame (m)."""
        return (np.asarray(points_tank, dtype=float) - np.asarray(self.position_m)) @ self.rotation

    @property
    def transmitter_position(self) -> NDArray[np.float64]:
        """Transmitter face centre (3,) in the tank frame (m)."""
        return self.head_to_tank(self.channel_positions_head[1:2])[0]

    @property
    def receiver_positions(self) -> NDArray[np.float64]:
        """Receiver face centres (3, 3) in the tank frame (m), rows left, centre, right."""
        return self.head_to_tank(self.channel_positions_head)

    @property
    def boresight(self) -> NDArray[np.float64]:
        """Unit vector (3,) of the acoustic axis in the tank frame."""
        return self.rotation[:, 1].copy()

    # ------------------------------------------------------------- signal side
    @property
    def pulse(self) -> GaussianPulse | SampledPulse:
        """The transmitted pulse (Pa at 1 m on axis)."""
        if self.custom_pulse is not None:
            return self.custom_pulse
        return GaussianPulse(self.centre_frequency_hz, self.pulse_duration_s, self.source_level_pa)

    @property
    def n_samples(self) -> int:
        """Samples per channel of one record."""
        return int(round(self.record_length_s * self.sample_rate_hz))

    def with_pose(
        self,
        position_m: tuple[float, float, float] | NDArray[np.float64],
        yaw_deg: float | None = None,
        pitch_deg: float | None = None,
        roll_deg: float | None = None,
    ) -> "SonarHead":
        """A copy of this head moved to a new pose (angles kept where not given)."""
        from dataclasses import replace

        return replace(
            self,
            position_m=tuple(float(v) for v in np.asarray(position_m, dtype=float)),
            yaw_deg=self.yaw_deg if yaw_deg is None else float(yaw_deg),
            pitch_deg=self.pitch_deg if pitch_deg is None else float(pitch_deg),
            roll_deg=self.roll_deg if roll_deg is None else float(roll_deg),
        )
