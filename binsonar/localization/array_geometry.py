"""Where the transmitter and the three receivers are, in the head frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True, eq=False)
class ArrayGeometry:
    """Transmitter and receiver positions of one sonar head (head frame, m).

    Attributes
    ----------
    transmitter_m : ndarray, shape (3,)
        Transmitter face centre.
    receivers_m : ndarray, shape (3, 3)
        Receiver face centres, rows left, centre, right. A bistatic path length L_i is the
        distance transmitter -> reflector -> receiver i.
    """

    transmitter_m: NDArray[np.float64] = field(repr=False)
    receivers_m: NDArray[np.float64] = field(repr=False)

    def __post_init__(self) -> None:
        t = np.array(self.transmitter_m, dtype=float)
        r = np.array(self.receivers_m, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f"array geometry: transmitter_m must be 3 finite numbers, got {self.transmitter_m!r}")
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise ValueError(f"array geometry: receivers_m must be (3, 3) finite, got shape {r.shape}")
        if np.linalg.norm(r[2] - r[0]) <= 0.0:
            raise ValueError("array geometry: the left and right receivers coincide")
        t.setflags(write=False)
        r.setflags(write=False)
        object.__setattr__(self, "transmitter_m", t)
        object.__setattr__(self, "receivers_m", r)

    @classmethod
    def seed(cls, separation_m: float) -> "ArrayGeometry":
        """The seed's head: transmitter and centre receiver at the origin, sides at x = -d, +d."""
        d = float(separation_m)
        if not (np.isfinite(d) and d > 0):
            raise ValueError(f"array geometry: separation_m must be > 0, got {separation_m!r}")
        return cls(np.zeros(3), np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]]))

    @classmethod
    def from_channel_positions(cls, channel_positions_m: ArrayLike, transmitter_channel: int = 1) -> "ArrayGeometry":
        """From a recording's channel positions (3, 3); the transmitter is one of them (the centre)."""
        pos = np.asarray(channel_positions_m, dtype=float)
        if pos.shape != (3, 3):
            raise ValueError(f"array geometry: channel positions must be (3, 3), got shape {pos.shape}")
        return cls(pos[transmitter_channel].copy(), pos)

    @property
    def half_baseline_m(self) -> float:
        """Half the left-right receiver distance (m): the seed's d for a symmetric head."""
        return 0.5 * float(np.linalg.norm(self.receivers_m[2] - self.receivers_m[0]))

    @property
    def max_path_difference_m(self) -> float:
        """Largest possible |L_left - L_right| (m): the left-right receiver distance (triangle inequality)."""
        return 2.0 * self.half_baseline_m

    def direct_distance_m(self) -> NDArray[np.float64]:
        """Transmitter-receiver distances (3,) (m): the shortest possible path length per channel."""
        return np.linalg.norm(self.receivers_m - self.transmitter_m, axis=1)

    @property
    def is_seed(self) -> bool:
        """True for the seed's symmetric collinear head (transmitter at the origin, sides at -d, +d on x)."""
        d = self.half_baseline_m
        expected = np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]])
        return bool(np.allclose(self.receivers_m, expected, rtol=0, atol=1e-12 * d)
                    and np.allclose(self.transmitter_m, 0.0, rtol=0, atol=1e-12 * d))
