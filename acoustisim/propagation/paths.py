"""The propagation engine's result: every transmitter-to-receiver path, as one structured array.

One row per path contribution and receiver channel. Specular, direct and diffuse paths are
one row each. An edge diffraction is a continuous line integral; the engine emits it as the
rows of its discretised edge elements (each a delayed, weighted impulse), all sharing one
``path_id``, so that their sum is the band-limited Biot-Tolstoy-Medwin impulse response.
:meth:`Paths.arrivals` collapses such groups into one row per physical arrival (the ground
truth table of ``conventions.md``).

Every row is the impulse response ``geometric_gain * delta(t - delay_s)`` with an extra
constant phase ``phase_rad`` (applied as exp(+j phase) on positive frequencies: speckle of
diffuse paths, complex reflection coefficients beyond the critical angle), to which synthesis
adds the frequency-dependent factors: directivities at ``angle_tx_rad`` / ``angle_rx_rad``,
absorption over ``path_length_m``, the coherent-roughness factor exp(-S k^2) of rows with
``roughness_m2`` S > 0, and the transfer function ``Paths.responses[response_id]`` of rows
that stand for a whole shaped echo (an elastic object's, a shadow's;
:mod:`acoustisim.propagation.responses`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

MAX_INTERACTIONS = 4
"""Most interaction points stored per path (specular order 3 plus one, or edge + 2)."""


class PathKind(enum.IntEnum):
    """What a path did between transmitter and receiver."""

    DIRECT = 0
    SPECULAR = 1
    EDGE = 2
    DIFFUSE = 3

    @property
    def label(self) -> str:
        """The lower-case name used in the arrivals table ("direct", "specular", ...)."""
        return self.name.lower()


PATH_DTYPE = np.dtype(
    [
        ("path_id", np.int64),  # rows of one physical arrival share it (edge elements)
        ("channel", np.int8),  # 0 left, 1 centre, 2 right
        ("kind", np.int8),  # PathKind
        ("order", np.int8),  # number of interactions
        ("delay_s", np.float64),  # travel time (s)
        ("path_length_m", np.float64),  # total length (m)
        ("geometric_gain", np.float64),  # spreading x reflection x curvature (x dz for edges), signed
        ("phase_rad", np.float64),  # extra constant phase (rad), 0 for most paths
        ("angle_tx_rad", np.float64),  # departure angle off the transmitter axis (rad)
        ("angle_rx_rad", np.float64),  # arrival angle off the receiver axis (rad)
        ("directivity_tx", np.float64),  # 2 J1(x)/x at the centre frequency
        ("directivity_rx", np.float64),  # 2 J1(x)/x at the centre frequency
        ("absorption_db", np.float64),  # at the centre frequency (dB, positive = loss)
        ("amplitude", np.float64),  # |echo pressure factor| at f0, coherent-roughness factor included
        ("departure_dir", np.float64, (3,)),  # unit vector leaving the transmitter (tank frame)
        ("arrival_dir", np.float64, (3,)),  # unit vector of propagation arriving at the receiver
        ("object_ids", np.int16, (MAX_INTERACTIONS,)),  # index into Paths.surface_names, -1 pad
        ("points_m", np.float64, (MAX_INTERACTIONS, 3)),  # interaction points, NaN pad
        ("roughness_m2", np.float64),  # S: coherent-roughness factor exp(-S k^2), 0 if smooth
        ("response_id", np.int32),  # index into Paths.responses (a transfer function), -1 none
    ]
)


def empty_paths_array(n: int = 0) -> NDArray[Any]:
    """A zero-filled path array of ``n`` rows with the padding conventions applied."""
    rows = np.zeros(n, dtype=PATH_DTYPE)
    rows["object_ids"] = -1
    rows["points_m"] = np.nan
    rows["response_id"] = -1
    return rows


def roughness_loss_db(roughness_m2: NDArray[np.float64], frequency_hz: float,
                      sound_speed_m_s: float) -> NDArray[np.float64]:
    """The coherent-roughness loss (dB, positive) -20 log10(exp(-S k^2)) = 20 S k^2 / ln 10 of
    rows with ``roughness_m2`` S (m^2), at ``frequency_hz`` (k = 2 pi f / c): what the factor
    already in ``amplitude`` (at f0) costs, as the arrivals table reports it."""
    k = 2.0 * np.pi * frequency_hz / sound_speed_m_s
    return np.asarray(roughness_m2, dtype=float) * (k * k * 20.0 / np.log(10.0))


@dataclass(frozen=True, eq=False)
class Paths:
    """Immutable, vectorised set of paths.

    Attributes
    ----------
    rows : structured ndarray, shape (n,), dtype PATH_DTYPE
        Read-only.
    surface_names : tuple of str
        Names indexed by ``rows["object_ids"]`` (the scene's boundaries then objects).
    centre_frequency_hz : float
        Frequency at which the scalar columns (directivity, absorption, amplitude) are given.
    sound_speed_m_s : float
        Sound speed used for the delays.
    responses : tuple of EchoResponse
        The transfer functions rows name by ``response_id``.
    """

    rows: NDArray[Any] = field(repr=False)
    surface_names: tuple[str, ...] = ()
    centre_frequency_hz: float = 500e3
    sound_speed_m_s: float = 1482.38
    responses: tuple[Any, ...] = ()

    def __post_init__(self) -> None:
        rows = np.array(self.rows, dtype=PATH_DTYPE, copy=True)
        rows.setflags(write=False)
        object.__setattr__(self, "rows", rows)

    @classmethod
    def adopt(cls, rows: NDArray[Any], surface_names: tuple[str, ...] = (), centre_frequency_hz: float = 500e3,
              sound_speed_m_s: float = 1482.38, responses: tuple[Any, ...] = ()) -> "Paths":
        """Paths owning ``rows`` without a copy: for a freshly built PATH_DTYPE array that the
        caller hands over (it is made read-only; keep no writable reference to it)."""
        if rows.dtype != PATH_DTYPE or rows.base is not None or not rows.flags.c_contiguous:
            return cls(rows, surface_names, centre_frequency_hz, sound_speed_m_s, tuple(responses))
        rows.setflags(write=False)
        paths = object.__new__(cls)
        for name, value in (("rows", rows), ("surface_names", surface_names),
                            ("centre_frequency_hz", centre_frequency_hz), ("sound_speed_m_s", sound_speed_m_s),
                            ("responses", tuple(responses))):
            object.__setattr__(paths, name, value)
        return paths

    def __len__(self) -> int:
        return int(self.rows.size)

    def __getitem__(self, key: str) -> NDArray[Any]:
        return self.rows[key]

    def select(self, mask: NDArray[np.bool_]) -> "Paths":
        """The subset of rows where ``mask`` is true."""
        return Paths(self.rows[mask], self.surface_names, self.centre_frequency_hz, self.sound_speed_m_s,
                     self.responses)

    def for_channel(self, channel: int) -> "Paths":
        """Rows of one receiver channel (0 left, 1 centre, 2 right)."""
        return self.select(self.rows["channel"] == channel)

    def object_labels(self) -> list[str]:
        """For each row, the names it touched, joined by '>' (empty for the direct path)."""
        names = np.asarray(self.surface_names + ("",), dtype=object)
        ids = np.where(self.rows["object_ids"] < 0, len(self.surface_names), self.rows["object_ids"])
        return [">".join(n for n in row if n) for row in names[ids]]

    def arrivals(self) -> NDArray[Any]:
        """One row per physical arrival: edge-element groups collapsed.

        A group's delay is its earliest element (the least-time point), its interaction points
        and directions those of that element, its ``geometric_gain`` and ``amplitude`` the
        magnitude of the group's complex sum at the centre frequency (the edge's transfer
        function there), signed like the earliest element.
        """
        rows = self.rows
        if rows.size == 0:
            return rows.copy()
        order = np.lexsort((rows["delay_s"], rows["channel"], rows["path_id"]))
        sorted_rows = rows[order]
        key = sorted_rows["path_id"].astype(np.int64) * 8 + sorted_rows["channel"]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        out = sorted_rows[starts].copy()
        group = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, key.size]))
        omega = 2.0 * np.pi * self.centre_frequency_hz
        phasor_geo = sorted_rows["geometric_gain"] * np.exp(
            1j * (sorted_rows["phase_rad"] - omega * (sorted_rows["delay_s"] - out["delay_s"][group]))
        )
        phasor_amp = sorted_rows["amplitude"] * np.sign(sorted_rows["geometric_gain"]) * np.exp(
            1j * (sorted_rows["phase_rad"] - omega * (sorted_rows["delay_s"] - out["delay_s"][group]))
        )
        geo = np.zeros(starts.size, dtype=complex)
        amp = np.zeros(starts.size, dtype=complex)
        np.add.at(geo, group, phasor_geo)
        np.add.at(amp, group, phasor_amp)
        multi = np.diff(np.r_[starts, key.size]) > 1
        sign = np.where(out["geometric_gain"] < 0, -1.0, 1.0)
        out["geometric_gain"] = np.where(multi, sign * np.abs(geo), out["geometric_gain"])
        out["amplitude"] = np.where(multi, np.abs(amp), out["amplitude"])
        out["phase_rad"] = np.where(multi, np.angle(geo * sign), out["phase_rad"])
        return out[np.lexsort((out["delay_s"], out["channel"]))]

    def arrivals_table(self) -> list[dict[str, Any]]:
        """The arrivals as JSON-ready dictionaries (columns of ``conventions.md``).

        Beyond those columns, ``roughness_loss_db``: the coherent-roughness loss at the centre
        frequency (dB, positive; 0 for smooth surfaces), 20 S k0^2 / ln 10 of the row's
        ``roughness_m2`` S (k0 = 2 pi f0 / c), already included in ``amplitude``
        (:mod:`acoustisim.propagation.roughness`).
        """
        arrivals = Paths(self.arrivals(), self.surface_names, self.centre_frequency_hz, self.sound_speed_m_s)
        labels = arrivals.object_labels()
        channel_names = ("left", "centre", "right")
        roughness_loss = roughness_loss_db(arrivals.rows["roughness_m2"], self.centre_frequency_hz,
                                           self.sound_speed_m_s)
        table = []
        for i, (row, label) in enumerate(zip(arrivals.rows, labels)):
            n = int(row["order"])
            table.append(
                {
                    "channel": channel_names[int(row["channel"])],
                    "delay_s": float(row["delay_s"]),
                    "kind": PathKind(int(row["kind"])).label,
                    "order": n,
                    "objects": label.split(">") if label else [],
                    "geometric_gain": float(row["geometric_gain"]),
                    "directivity_tx": float(row["directivity_tx"]),
                    "directivity_rx": float(row["directivity_rx"]),
                    "absorption_db": float(row["absorption_db"]),
                    "amplitude": float(row["amplitude"]),
                    "roughness_loss_db": float(roughness_loss[i]),
                    "path_length_m": float(row["path_length_m"]),
                    "departure_dir": [float(v) for v in row["departure_dir"]],
                    "arrival_dir": [float(v) for v in row["arrival_dir"]],
                    "points_m": [[float(v) for v in p] for p in row["points_m"][: min(n, MAX_INTERACTIONS)]],
                }
            )
        return table
