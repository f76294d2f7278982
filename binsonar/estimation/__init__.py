"""What accuracy is possible: Cramer-Rao bounds on times of flight and on target positions.

``binsonar.bounds`` holds the white-noise bound of a template (what a detector reports as
``Echo.tof_std_s``); ``tof`` the bounds of a given echo in given noise (coloured, or with
reverberation at its local level), and the matched filter's output SNR that they take;
``position`` their propagation through the seed's point localiser to range and bearing.
Importing this package loads numpy only.
"""

from binsonar.estimation.position import (
    NoiseBound,
    PointBound,
    ReverberationBound,
    noise_bound,
    point_bound,
    reverberation_bound,
)
from binsonar.estimation.tof import (
    EchoBound,
    InterferenceSnr,
    analytic_correlation,
    echo_tof_crlb_s,
    interference_snr,
    matched_snr,
)

__all__ = (
    "EchoBound",
    "InterferenceSnr",
    "NoiseBound",
    "PointBound",
    "ReverberationBound",
    "analytic_correlation",
    "echo_tof_crlb_s",
    "interference_snr",
    "matched_snr",
    "noise_bound",
    "point_bound",
    "reverberation_bound",
)
