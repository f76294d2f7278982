"""Detected echoes: what every detector returns."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Echo:
    """One detected echo on one channel of one ping.

    Attributes
    ----------
    channel : int
        0 left, 1 centre, 2 right.
    tof_s : float
        Time of flight (s) from the transmit trigger to the echo's reference instant (the
        template's reference, e.g. the Gaussian pulse's envelope peak).
    amplitude : float
        Detector-specific amplitude (V for the matched filter's envelope peak normalised by the
        template energy, i.e. the echo's estimated peak amplitude).
    snr_db : float
        Estimated 2E/N0 of the echo (dB).
    score : float
        Detection statistic divided by the detector's threshold (> 1 means detected).
    ping : int
        Index of the ping (0 after averaging).
    tof_std_s : float
        Estimated standard deviation of ``tof_s`` (s): the CRLB at the estimated SNR, or the
        detector's own bias/std model; NaN when unknown.
    clipped : bool
        The channel clipped in this ping: the echo is unreliable.
    """

    channel: int
    tof_s: float
    amplitude: float
    snr_db: float
    score: float
    ping: int = 0
    tof_std_s: float = float("nan")
    clipped: bool = False


@dataclass(frozen=True)
class DetectionResult:
    """Echoes of every ping and channel, from one method.

    Attributes
    ----------
    method : str
        The method's name.
    echoes : tuple (n_pings) of tuple (3 channels) of tuple of Echo
        Sorted by time of flight within a channel.
    elapsed_s : float
        Processing time of the detection (s), excluding file reading.
    clipped : tuple (n_pings) of tuple (3) of bool
        Channels whose samples clipped (echoes there are unreliable).
    options : tuple of (str, value)
        The options used.
    """

    method: str
    echoes: tuple[tuple[tuple[Echo, ...], ...], ...]
    elapsed_s: float = 0.0
    clipped: tuple[tuple[bool, ...], ...] = ()
    options: tuple[tuple[str, object], ...] = field(default=())

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return len(self.echoes)

    def first(self, ping: int = 0) -> tuple[Echo | None, Echo | None, Echo | None]:
        """The earliest echo of each channel of one ping (None where nothing was detected)."""
        return tuple(ch[0] if ch else None for ch in self.echoes[ping])  # type: ignore[return-value]

    def strongest(self, ping: int = 0) -> tuple[Echo | None, Echo | None, Echo | None]:
        """The highest-scoring echo of each channel of one ping."""
        return tuple(max(ch, key=lambda e: e.score) if ch else None for ch in self.echoes[ping])  # type: ignore[return-value]
