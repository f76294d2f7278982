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

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from acoustisim import checks, ranges
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
        owner = "sonar"
        set_ = object.__setattr__
        set_(self, "position_m", checks.vector(owner, "position_m", self.position_m, 3, ranges.COORDINATE_M))
        for name in ("yaw_deg", "pitch_deg", "roll_deg"):
            set_(self, name, checks.real(owner, name, getattr(self, name), ranges.ANGLE_DEG))
        for name, allowed in (
            ("separation_m", ranges.LENGTH_M),
            ("transducer_diameter_m", ranges.LENGTH_M),
            ("centre_frequency_hz", ranges.CENTRE_FREQUENCY_HZ),
            ("pulse_duration_s", ranges.PULSE_DURATION_S),
            ("source_level_pa", ranges.SOURCE_LEVEL_PA),
            ("sample_rate_hz", ranges.SAMPLE_RATE_HZ),
            ("record_length_s", ranges.RECORD_LENGTH_S),
        ):
            set_(self, name, checks.real(owner, name, getattr(self, name), allowed))
        set_(self, "adc_bits", checks.integer(owner, "adc_bits", self.adc_bits,
                                              minimum=int(ranges.ADC_BITS.low), maximum=int(ranges.ADC_BITS.high)))
        if self.channel_positions_m is not None:
            rows = self.channel_positions_m
            if isinstance(rows, np.ndarray) and rows.ndim == 2:
                rows = list(rows)
            if not isinstance(rows, (list, tuple)):
                raise checks.type_error(owner, "channel_positions_m", rows, "three rows [x, y, z] (left, centre, right)")
            if len(rows) != 3:
                raise checks.value_error(owner, "channel_positions_m", rows,
                                         "expected three rows [x, y, z] (left, centre, right)")
            set_(self, "channel_positions_m", tuple(
                checks.vector(owner, f"channel_positions_m[{i}]", row, 3, ranges.COORDINATE_M)
                for i, row in enumerate(rows)))
        if self.custom_pulse is not None:
            checks.instance(owner, "custom_pulse", self.custom_pulse, SampledPulse, "a SampledPulse or None")
        self._check_layout()

    def _check_layout(self) -> None:
        """Refuse transducers whose face centres are closer than a piston radius: two pistons
        cannot share a place, and the solver would meet a receiver inside the transmitter."""
        rows = self.channel_positions_head
        a = self.piston_radius_m
        for i, j in ((0, 1), (2, 1), (0, 2)):
            gap = float(np.linalg.norm(rows[i] - rows[j]))
            if gap < a:
                key = "channel_positions_m" if self.channel_positions_m is not None else "separation_m"
                value = self.channel_positions_m if self.channel_positions_m is not None else self.separation_m
                raise checks.value_error(
                    "sonar", key, value,
                    f"the {CHANNEL_NAMES[i]} transducer coincides with the {CHANNEL_NAMES[j]} one ({gap:.3g} m apart,"
                    f" less than the piston radius {a:g} m of sonar.transducer_diameter_m = {self.transducer_diameter_m!r})")

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
