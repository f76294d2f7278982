"""Joint search over the three channels: targets whose echo crosses the detector on one channel or none.

Physics
-------
``localize`` starts from echoes that cross the CA-CFAR (false-alarm probability 1e-6 per cell)
on two channels (the cued search, ``beam_cue``, finds the third). A weak diffracting edge next
to a strong one (the prism's apex, 2E/N0 of 11-16 dB per channel at the plain matched filter)
crosses on two channels in about half the pings, yet its three channels together hold 19 dB:
enough for a detector that adds the channels along a hypothesised position. For a reflector at
head-frame position p, channel c's echo arrives at L_c(p) / c, L_c the transmitter -> p ->
receiver c path. With z_c the plain matched filter's analytic output and N_c its noise level
(mean |z|^2 of noise), X_c = |z_c|^2 / N_c is a unit exponential on noise (the complex
Gaussian's squared modulus), independent between channels (independent receiver noise). The
sum over K channels at the hypothesised delays is Gamma(K, 1) on noise (chi-square with 2K
degrees of freedom, halved),

    P(sum_K X_c > t) = exp(-t) sum_{i<K} t^i / i!,

and an echo of 2E/N0 = s_c adds s_c / 2 to its channel's mean (``refine_target``'s convention
2E/N0 = 2 |z_s|^2 / E|n|^2). The level N_c is estimated from M independent cells, as the
CA-CFAR's is: X_c / g_c (g_c the estimate over the truth, Gamma(M, 1/M)) has the tail
(1 + x / M)^-M, and the sum's law is the K-fold convolution of that (``SumTail``), a little
heavier than the Gamma's.

Method
------
1. The plain matched filter's decimated envelope per channel (``detection.matched``). A first
   level, the running median over +/- ``NOISE_HALF_WINDOW_S`` / ln 2, finds each detected
   echo's cells (``echo_cells``: +/- its main lobe and tolerance, and the run around it where
   the max-filtered X stays above ``SKIRT_LEVEL``: side lobes, an edge's tail, ringing). The
   level the test uses is the mean |z|^2 within +/- ``LOCAL_HALF_WINDOW_S`` over the cells no
   echo claims (``censored_mean``: local, as the CFAR's reference cells, so that the
   reverberation rising before a wall counts as noise); cells whose window is less than
   ``KEPT_FRACTION`` echo-free are not tested. X_c is max-filtered over +/-
   ``JointSearchConfig.tolerance_s`` (the plain filter's beam bias off axis, the grid's steps).
2. Hypotheses (``JointSetup``): the centre channel's delay every ``CELL_STRIDE`` cells fixes
   the range (the centre transducer transmits and receives: r = c t / 2), and bearings over the
   transmitter's main lobe (its first null at the template's centroid frequency), half the
   bearing resolution c tau_c / (2 d) apart (tau_c the envelope's correlation time, d the half
   baseline). Each (range, bearing) predicts the three delays (exact path lengths, near field
   included).
3. Two families of hypotheses, tested separately (a union bound adds their false alarms):

   - Unseeded: no channel's delay falls on a detected echo. Statistic: the sum of the three
     X_c; threshold for ``scan_pfa`` per ping over the scan's effective hypotheses.
   - Seeded: exactly one channel's delay falls on an echo that no target uses (it crossed the
     CFAR on that channel alone). The seed's own energy is no evidence of a target (a
     multipath or interference seen by one receiver has it too): the statistic is the sum of
     the two other channels' X_c; threshold for ``seed_pfa`` per seed over its hypotheses (the
     cells the seed claims times the bearings: its range shell fixes the rest).

   Delays on an echo a target uses, or on detected echoes of two channels, are the
   association's business and are not tested. The numbers of hypotheses
   (``effective_hypotheses``) are union bounds: independent cells every tau_c, independent
   bearings every c tau_c / d, and each max-filtered channel m = 1 + 2 tolerance / tau_c cells
   (m^K combinations); the per-hypothesis false-alarm probability is the budget over that.
4. Above-threshold hypotheses are taken strongest first (by their tail probability against
   their threshold's), one per seed and one per +/- ``exclusion_s`` of centre delay, at most
   ``max_targets``; each gives three delays (the seed's TOF, and on the other channels the
   plain filter's maximum within the tolerance of the prediction), which the pipeline times
   with the beam model and fits like any group (``pipeline.joint_targets``).

Accuracy
--------
The union bounds make the stated false-alarm probabilities upper bounds: on white noise
(410 us records, 200 pings, both families at 0.3) the measured rates are 0.09 (unseeded) and
0.13 (seeded; ``tests/physics/test_joint_search_physics.py``). The power: a point target at
1 m with 2E/N0 = 14.5 dB per channel, where the CFAR crosses on one channel or none in 29 of
40 pings, is reported (within 5 mm and 1 deg) in 27 of those 29; issue 19's trap (the prism's
apex at 1.3 m and 8 deg of yaw, 11-16 dB per channel) in 19 of 20 pings, against 6 without the
search (``benchmarks/localization_table.py``). A miss or a poorer location comes from the
strongest hypothesis landing on a neighbouring bearing, whose three delays the refinement's
+/- 6 us search cannot bring back. Cost: about 0.1 s per ping of 3 x 400,000 samples, most of
it the record-size matched filter and the gathers of 31 bearings x 50,000 ranges
(``benchmarks/bench_joint_search.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.errors import InputError

CELL_STRIDE = 4
"""Centre-channel cells between range hypotheses (after the max filter, which covers them)."""
NOISE_HALF_WINDOW_S = 0.25e-3
"""Half-width (s) of the running median that sets each channel's local noise level."""
LOCAL_HALF_WINDOW_S = 0.1e-3
"""Half-width (s) of the censored running mean that sets each channel's noise level for the
test: local enough to follow the reverberation's rise before a wall (as the CFAR's own
reference cells do), long enough (2 x 42 correlation times) that its estimation error costs
little (``SumTail``)."""
SKIRT_LEVEL = 4.0
"""X_c above which cells next to a detected echo are counted as that echo's (its side lobes and
tail): noise exceeds it in 1.8 % of cells (exp(-4)), so in noise the run stops within a cell or two."""
MAX_EXAMINED = 20000
"""At most this many above-threshold hypotheses (strongest first) are examined for distinct detections."""
TAIL_STEP = 0.01
"""Grid step of ``SumTail`` (units of the noise level): thresholds to about a hundredth."""
TAIL_MAX = 150.0
"""Grid end of ``SumTail``: beyond any threshold used (P(sum > 150) < 1e-40 for M >= 40)."""
KEPT_FRACTION = 0.75
"""A cell is tested where at least this fraction of its noise window is free of detected echoes:
its level then rests on at least KEPT_FRACTION x 2 ``LOCAL_HALF_WINDOW_S`` / tau_c independent cells."""
FIRST_NULL_X = 3.8317059702075125
"""First zero of J1: a piston's first null at (2 pi f / c) a sin(theta) equal to it."""


@dataclass(frozen=True)
class JointSearchConfig:
    """Settings of the joint multi-channel search (module docstring).

    Attributes
    ----------
    enabled : bool
        Run the search (needs the beam-aware pipeline: the recording's template and pistons).
    scan_pfa : float
        False-alarm probability per ping of the unseeded family (three channels summed).
    seed_pfa : float
        False-alarm probability per seed (an echo detected on one channel only).
    tolerance_s : float
        Each channel's delay is searched within this of its prediction (s): the plain filter's
        beam bias and the hypothesis grid's quantisation.
    exclusion_s : float
        Two joint detections are at least this far apart in centre delay (s).
    max_targets : int
        At most this many joint detections per ping.
    """

    enabled: bool = True
    scan_pfa: float = 1e-3
    seed_pfa: float = 1e-3
    tolerance_s: float = 1e-6
    exclusion_s: float = 20e-6
    max_targets: int = 4

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise InputError(f"joint search: enabled must be True or False, got {self.enabled!r}")
        for name in ("scan_pfa", "seed_pfa"):
            value = getattr(self, name)
            if not (isinstance(value, float) and 0.0 < value < 1.0):
                raise InputError(f"joint search: {name} must be a float in (0, 1), got {value!r}")
        for name in ("tolerance_s", "exclusion_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and 0.0 < value <= 1e-3):
                raise InputError(f"joint search: {name} must be within (0, 1e-3] s, got {value!r}")
        if not (isinstance(self.max_targets, int) and self.max_targets >= 0):
            raise InputError(f"joint search: max_targets must be an integer >= 0, got {self.max_targets!r}")


@dataclass(frozen=True, eq=False)
class JointDetection:
    """One above-threshold hypothesis.

    Attributes
    ----------
    tof_s : ndarray, shape (3,)
        Each channel's delay (s): the seed's TOF on its channel, elsewhere the plain filter's
        maximum within the tolerance of the prediction.
    amplitude_v : ndarray, shape (3,)
        The plain filter's amplitude estimate there (V, as the detectors').
    bearing_deg : float
        The hypothesis's bearing (deg).
    statistic : float
        The summed X_c of the tested channels.
    threshold : float
        Its family's threshold.
    seed : tuple of (int, int) or None
        (channel, index in that channel's echoes) of the seed; None for the unseeded family.
    """

    tof_s: NDArray[np.float64] = field(repr=False)
    amplitude_v: NDArray[np.float64] = field(repr=False)
    bearing_deg: float
    statistic: float
    threshold: float
    seed: tuple[int, int] | None


def effective_hypotheses(duration_s: ArrayLike, correlation_time_s: float, bearings: float, tolerance_s: float,
                         channels: int) -> NDArray[np.float64]:
    """Union-bound count of independent hypotheses: (duration / tau_c + 1) x bearings x m^channels,
    m = 1 + 2 tolerance / tau_c the independent cells each channel's max filter spans."""
    m = 1.0 + 2.0 * tolerance_s / correlation_time_s
    return (np.asarray(duration_s, dtype=float) / correlation_time_s + 1.0) * max(bearings, 1.0) * m ** channels


def main_lobe_half_angle_rad(template: Any, transducers: Any, sound_speed_m_s: float) -> float:
    """The transmitter's first null (rad) at the template's spectral centroid frequency."""
    s = np.asarray(template.samples, dtype=float)
    spectrum = np.abs(np.fft.rfft(s, 4 * s.size)) ** 2
    f = np.fft.rfftfreq(4 * s.size, 1.0 / float(template.sample_rate_hz))
    centroid = float(np.sum(f * spectrum) / np.sum(spectrum))
    radius = float(transducers.radii_m[transducers.transmitter_channel])
    sine = FIRST_NULL_X * sound_speed_m_s / (2.0 * math.pi * centroid * radius)
    return math.asin(min(sine, 1.0))


@dataclass(frozen=True, eq=False)
class SumTail:
    """The tail P(sum_k X_c / g_c > t) of k channels' statistics with estimated noise levels (``of``).

    X_c is a unit exponential (the noise's |z|^2 over its mean) and g_c the level's estimate over
    the true one, the mean of M independent reference cells: X_c / g_c has the tail
    (1 + x / M)^-M (the CA-CFAR's law; k F(2, 2M) / k). The channels' estimates are independent, so
    the sum's law is the k-fold convolution of that, computed on a grid. M to infinity gives the
    Gamma(k, 1) tail exp(-t) sum_{i<k} t^i / i!.

    Attributes
    ----------
    channels : int
        k.
    reference_cells : float
        M.
    t : ndarray, shape (n,)
        Grid of thresholds (``TAIL_STEP`` apart).
    log_tail : ndarray, shape (n,)
        ln P(sum > t) on the grid.
    """

    channels: int
    reference_cells: float
    t: NDArray[np.float64] = field(repr=False)
    log_tail: NDArray[np.float64] = field(repr=False)

    @classmethod
    def of(cls, channels: int, reference_cells: float) -> "SumTail":
        """The tail for k = ``channels`` and M = ``reference_cells``."""
        from scipy.signal import fftconvolve

        m = float(reference_cells)
        x = np.arange(0.0, TAIL_MAX, TAIL_STEP)
        single = np.exp(-m * np.log1p(x / m))  # P(X / g > x)
        mass = -np.diff(np.append(single, 0.0))  # exact probability of each grid cell (the last: the rest)
        density = mass
        for _ in range(channels - 1):
            density = np.maximum(fftconvolve(density, mass)[: x.size], 0.0)
        tail = np.cumsum(density[::-1])[::-1]  # P(sum >= t), summed from the far end (no cancellation)
        tail = np.append(tail[1:], 0.0)  # P(sum > t): the cell at t itself excluded (conservative grid)
        log_tail = np.log(np.maximum(tail, np.finfo(float).tiny))
        x.setflags(write=False)
        log_tail.setflags(write=False)
        return cls(int(channels), m, x, log_tail)

    def threshold(self, pfa: ArrayLike) -> NDArray[np.float64]:
        """t with P(sum > t) = pfa (elementwise, interpolated in ln P)."""
        target = np.log(np.asarray(pfa, dtype=float))
        return np.interp(-target, -self.log_tail, self.t)

    def log_probability(self, t: ArrayLike) -> NDArray[np.float64]:
        """ln P(sum > t) (elementwise; linear extrapolation in t beyond the grid)."""
        values = np.asarray(t, dtype=float)
        inside = np.interp(values, self.t, self.log_tail)
        slope = (self.log_tail[-1] - self.log_tail[-101]) / (self.t[-1] - self.t[-101])
        return np.where(values > self.t[-1], self.log_tail[-1] + slope * (values - self.t[-1]), inside)


def censored_mean(power: NDArray[np.float64], keep: NDArray[np.bool_], half_cells: int,
                  stride: int = 1) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Running mean (n_rows, n) of ``power`` over the cells within +/- ``half_cells`` where ``keep``,
    and how many cells it used (cumulative sums, O(n)); from every ``stride``-th cell (the
    envelope's cells are correlated over many: the subsample loses nothing), counts scaled back."""
    n = power.shape[1]
    sub_keep = keep[:, ::stride]
    values = np.concatenate([np.zeros((power.shape[0], 1)), np.cumsum(np.where(sub_keep, power[:, ::stride], 0.0),
                                                                       axis=1)], axis=1)
    counts = np.concatenate([np.zeros((power.shape[0], 1)), np.cumsum(sub_keep, axis=1)], axis=1)
    m = sub_keep.shape[1]
    position = np.arange(n) // stride
    half = max(1, half_cells // stride)
    lo = np.clip(position - half, 0, m)
    hi = np.clip(position + half + 1, 0, m)
    used = counts[:, hi] - counts[:, lo]
    return (values[:, hi] - values[:, lo]) / np.maximum(used, 1.0), used * stride


def local_noise(power: NDArray[np.float64], cells: int, stride: int) -> NDArray[np.float64]:
    """Mean noise |z|^2 per cell (n_rows, n): the median of |z|^2 over +/- ``cells`` / ln 2 (the
    exponential's median is ln 2 times its mean; robust to echoes, which occupy few of the cells),
    from the ``stride``-cell subsample, at window centres ``cells`` / 4 apart, interpolated between."""
    n = power.shape[1]
    sub = power[:, ::stride]
    half = max(1, cells // stride)
    if sub.shape[1] <= 2 * half + 1:
        level = np.median(sub, axis=1, keepdims=True) / math.log(2.0)
        return np.maximum(np.broadcast_to(level, power.shape), np.finfo(float).tiny)
    padded = np.pad(sub, ((0, 0), (half, half)), mode="reflect")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=1)
    step = max(1, half // 4)
    centres = np.arange(0, sub.shape[1], step)
    median = np.median(windows[:, centres, :], axis=2) / math.log(2.0)
    positions = centres * stride
    floor = np.finfo(float).tiny
    return np.maximum(np.stack([np.interp(np.arange(n), positions, row) for row in median]), floor)


def joint_search(rows: NDArray[np.float64], setup: "JointSetup", *, t0_s: float, transmitter_m: NDArray[np.float64],
                 receivers_m: NDArray[np.float64], echoes: Sequence[Sequence[Any]], used: Sequence[Sequence[bool]],
                 min_range_m: float = 0.05) -> list[JointDetection]:
    """Targets found by adding the channels along hypothesised positions (module docstring).

    Parameters
    ----------
    rows : ndarray, shape (3, n)
        The ping's channels (V), left, centre, right.
    setup : JointSetup
        The plain matched filter, the bearings and the scan's threshold for this record length.
    t0_s : float
        Time of sample 0 after the trigger (s).
    transmitter_m, receivers_m : ndarray, shapes (3,) and (3, 3)
        Head-frame positions (m); the centre receiver is at the transmitter.
    echoes : sequence of 3 sequences of Echo
        The ping's detected echoes per channel.
    used : sequence of 3 sequences of bool
        Whether each detected echo belongs to a target already.
    min_range_m : float
        Ranges below this are not hypothesised (m).

    Returns
    -------
    list of JointDetection
        Strongest first.
    """
    from scipy.ndimage import maximum_filter1d

    from binsonar.detection.matched import envelope, filtered_spectrum

    plan, config = setup.plan, setup.config
    fs = float(plan.sample_rate_hz)
    c = setup.sound_speed_m_s
    cell_s = plan.decimation / fs
    tau_c = float(plan.correlation_time_s)
    x = np.asarray(rows, dtype=float)
    z = envelope(plan, filtered_spectrum(plan, x, dc=x.mean(axis=1)))
    power = z.real ** 2 + z.imag ** 2
    n_cells = power.shape[1]
    stride_noise = max(1, int(round(tau_c / cell_s)))
    ratio = power / local_noise(power, int(round(NOISE_HALF_WINDOW_S / cell_s)), stride_noise)
    w = setup.tolerance_cells
    best = maximum_filter1d(ratio, 2 * w + 1, axis=1, mode="nearest")
    # Detected echoes: a label per cell (-1 none), and whether the pipeline used it.
    offset_s = t0_s - plan.template.t0_s  # tof of cell j is offset_s + j cell_s

    def cell_of(tof: NDArray[np.float64]) -> NDArray[np.intp]:
        return np.rint((np.asarray(tof) - offset_s) / cell_s).astype(np.intp)

    guard = int(math.ceil((plan.mainlobe_fwhm_s + config.tolerance_s) / cell_s))
    label, taken, span = echo_cells(best, [cell_of(np.array([e.tof_s for e in ch], dtype=float)) for ch in echoes],
                                    used, guard)
    # The local noise level: the mean |z|^2 of the cells within +/- LOCAL_HALF_WINDOW_S that no
    # detected echo claims (a censored CA estimate; the first pass above only found the claims).
    half_cells = int(round(LOCAL_HALF_WINDOW_S / cell_s))
    level, kept = censored_mean(power, label < 0, half_cells, stride_noise)
    reliable = kept >= KEPT_FRACTION * (2 * half_cells + 1)
    ratio = np.where(reliable, power / np.maximum(level, np.finfo(float).tiny), 0.0)
    best = maximum_filter1d(ratio, 2 * w + 1, axis=1, mode="nearest")
    bearings = setup.bearings_rad
    centre = np.arange(0, n_cells, CELL_STRIDE)
    radius = c * (offset_s + centre * cell_s) / 2.0
    centre = centre[radius >= min_range_m]
    radius = radius[radius >= min_range_m]
    t_scan = setup.scan_threshold
    # A seed's hypotheses: the seed channel's delay anywhere on the echo's claimed cells, every
    # bearing (its range shell fixes the rest); its threshold from their number.
    widest = max(1, max(len(spans) for spans in span))
    seed_thresholds = np.full((3, widest + 1), math.inf)  # (channel, echo index); the last column: no echo
    for ch, spans in enumerate(span):
        seed_thresholds[ch, :len(spans)] = setup.seed_threshold(np.asarray(spans, dtype=float) * cell_s)
    t_seed = float(seed_thresholds.min())
    found: list[NDArray[np.float64]] = []  # rows (log tail margin, statistic, k, bearing, hypothesis, seed ch, seed i)
    t_least = min(t_scan, t_seed)  # a hypothesis whose three channels sum below it passes neither test
    offsets = transmitter_m[np.newaxis, :] - receivers_m  # (3, 3): transmitter minus each receiver
    offset_sq = np.sum(offsets ** 2, axis=1)
    inv_cell = 1.0 / (c * cell_s)
    first_cell = offset_s / cell_s
    for j, theta in enumerate(bearings):  # tens of bearings, each vectorised over every range
        direction = np.array([math.sin(theta), math.cos(theta), 0.0])
        # |p - rx_c| for p = tx + r u: sqrt(r^2 + 2 r u.(tx - rx_c) + |tx - rx_c|^2) (near field exact).
        along = offsets @ direction
        cells = [np.rint((radius + np.sqrt(radius * radius + 2.0 * radius * along[ch] + offset_sq[ch])) * inv_cell
                         - first_cell).astype(np.intp) for ch in range(3)]
        total = np.zeros(radius.size)
        inside = np.ones(radius.size, dtype=bool)
        for ch in range(3):
            inside &= (cells[ch] >= 0) & (cells[ch] < n_cells)
            total += best[ch, np.clip(cells[ch], 0, n_cells - 1)]
        hot = np.flatnonzero(inside & (total > t_least))  # the few hypotheses worth the labels
        if hot.size == 0:
            continue
        hot_cells = np.stack([cells[ch][hot] for ch in range(3)], axis=1)  # (m, 3)
        values = np.stack([best[ch, hot_cells[:, ch]] for ch in range(3)], axis=1)
        labels = np.stack([label[ch, hot_cells[:, ch]] for ch in range(3)], axis=1)
        touched = labels >= 0
        n_touched = touched.sum(axis=1)
        seed_channel = np.argmax(touched, axis=1)
        rows_h = np.arange(hot.size)
        seed_index = labels[rows_h, seed_channel]
        free = ~taken[seed_channel, hot_cells[rows_h, seed_channel]]
        seeded_sum = np.where(touched, 0.0, values).sum(axis=1)
        seed_threshold = seed_thresholds[seed_channel, seed_index]  # index -1: the no-echo column (inf)
        unseeded = (n_touched == 0) & (total[hot] > t_scan)
        seeded = (n_touched == 1) & free & (seeded_sum > seed_threshold)
        for mask, stat, k, t in ((unseeded, total[hot], 3, np.full(hot.size, t_scan)),
                                 (seeded, seeded_sum, 2, seed_threshold)):
            if mask.any():
                tail = setup.tails[k - 2]
                margin = tail.log_probability(t[mask]) - tail.log_probability(stat[mask])
                ch = seed_channel[mask] if k == 2 else np.full(mask.sum(), -1)
                idx = seed_index[mask] if k == 2 else np.full(mask.sum(), -1)
                found.append(np.column_stack([margin, stat[mask], np.full(mask.sum(), k), np.full(mask.sum(), j),
                                              hot[mask], ch, idx, t[mask]]))
    if not found:
        return []
    table = np.concatenate(found)
    table = table[np.argsort(-table[:, 0], kind="stable")]
    out: list[JointDetection] = []
    taken_seeds: set[tuple[int, int]] = set()
    taken_delays: list[float] = []
    for _, statistic, k, j, h, seed_ch, seed_i, threshold in table[:MAX_EXAMINED]:
        if len(out) >= config.max_targets:
            break
        h, j = int(h), int(j)
        seed = None if k == 3 else (int(seed_ch), int(seed_i))
        delay = offset_s + centre[h] * cell_s
        if seed is not None and seed in taken_seeds:
            continue
        if any(abs(delay - d) < config.exclusion_s for d in taken_delays):
            continue
        theta = float(bearings[j])
        direction = np.array([math.sin(theta), math.cos(theta), 0.0])
        p = transmitter_m + radius[h] * direction
        lengths = np.linalg.norm(p - transmitter_m) + np.linalg.norm(p[np.newaxis, :] - receivers_m, axis=1)
        predicted = cell_of(lengths / c)
        tof = np.empty(3)
        peak_power = np.empty(3)
        for ch in range(3):
            if seed is not None and ch == seed[0]:
                tof[ch] = float(echoes[ch][seed[1]].tof_s)
                peak_power[ch] = power[ch, int(np.clip(cell_of(np.array(tof[ch])), 0, n_cells - 1))]
                continue
            lo, hi = max(0, predicted[ch] - w), min(n_cells, predicted[ch] + w + 1)
            at = lo + int(np.argmax(ratio[ch, lo:hi]))
            tof[ch] = offset_s + at * cell_s
            peak_power[ch] = power[ch, at]
        amplitude = np.sqrt(peak_power) / plan.peak_response * float(np.max(np.abs(plan.template.samples)))
        out.append(JointDetection(tof, amplitude, math.degrees(theta), float(statistic), float(threshold), seed))
        taken_delays.append(delay)
        if seed is not None:
            taken_seeds.add(seed)
    return out


def echo_cells(best: NDArray[np.float64], echo_cell: Sequence[NDArray[np.intp]], used: Sequence[Sequence[bool]],
               guard: int) -> tuple[NDArray[np.intp], NDArray[np.bool_], list[NDArray[np.intp]]]:
    """Which cells belong to a detected echo, per channel: its index (-1 none), whether a target
    uses it, and each echo's number of cells (a list of 3 arrays).

    An echo claims +/- ``guard`` cells and the whole run of cells around it where ``best`` (the
    max-filtered X) stays above ``SKIRT_LEVEL``: its side lobes, an edge's diffraction tail, a
    body's ringing. Its energy there is the echo's, not evidence of another target.
    """
    n_rows, n_cells = best.shape
    label = np.full((n_rows, n_cells), -1, dtype=np.intp)
    taken = np.zeros((n_rows, n_cells), dtype=bool)
    quiet = best <= SKIRT_LEVEL
    spans = [np.zeros(len(echo_cell[ch]), dtype=np.intp) for ch in range(n_rows)]
    for ch in range(n_rows):  # three channels, each with its few detected echoes
        for i, k in enumerate(np.asarray(echo_cell[ch], dtype=np.intp)):
            k = int(np.clip(k, 0, n_cells - 1))
            lo, hi = max(0, k - guard), min(n_cells, k + guard + 1)
            before = np.flatnonzero(quiet[ch, :lo])
            after = np.flatnonzero(quiet[ch, hi:])
            lo = int(before[-1]) + 1 if before.size else 0  # the run above the level reaching the guard
            hi = hi + int(after[0]) if after.size else n_cells
            label[ch, lo:hi] = i
            taken[ch, lo:hi] |= bool(used[ch][i])
            spans[ch][i] = hi - lo
    return label, taken, spans




@dataclass(frozen=True, eq=False)
class JointSetup:
    """What the joint search takes for a recording besides each ping's samples (``create``).

    Attributes
    ----------
    plan : binsonar.detection.matched.MatchedPlan
        The plain matched filter for the record's length (with its record-size spectrum).
    bearings_rad : ndarray, shape (b,)
        The hypothesised bearings: over the transmitter's main lobe
        (``main_lobe_half_angle_rad``), half the bearing resolution c tau_c / (2 d) apart.
    independent_bearings : float
        The number of independent bearings, 2 theta_null / (c tau_c / d) + 1.
    scan_threshold : float
        The unseeded family's threshold on the three channels' sum.
    sound_speed_m_s : float
    config : JointSearchConfig
    tails : tuple of SumTail
        The null laws of the seeded (two channels) and unseeded (three) statistics.
    """

    plan: Any = field(repr=False)
    bearings_rad: NDArray[np.float64] = field(repr=False)
    independent_bearings: float
    scan_threshold: float
    sound_speed_m_s: float
    config: JointSearchConfig
    tails: tuple[SumTail, SumTail] = field(repr=False)

    @classmethod
    def create(cls, template: Any, transducers: Any, n_samples: int, sample_rate_hz: float, sound_speed_m_s: float,
               receivers_m: ArrayLike, config: JointSearchConfig) -> "JointSetup":
        """The plan, the bearings and the scan's threshold for records of ``n_samples`` samples."""
        from binsonar.detection.matched import plan_matched

        plan = plan_matched(template, int(n_samples), float(sample_rate_hz))
        c = float(sound_speed_m_s)
        rx = np.asarray(receivers_m, dtype=float)
        half_baseline = 0.5 * float(np.linalg.norm(rx[2] - rx[0]))
        tau_c = float(plan.correlation_time_s)
        lobe = main_lobe_half_angle_rad(template, transducers, c)
        step = c * tau_c / (4.0 * half_baseline)  # half the bearing resolution c tau_c / (2 d)
        bearings = np.linspace(-lobe, lobe, 2 * int(math.ceil(lobe / step)) + 1)
        independent = 2.0 * lobe / (c * tau_c / half_baseline) + 1.0
        duration = plan.n_valid * plan.decimation / float(sample_rate_hz)
        count = effective_hypotheses(duration, tau_c, independent, config.tolerance_s, 3)
        reference = KEPT_FRACTION * 2.0 * LOCAL_HALF_WINDOW_S / tau_c
        tails = (SumTail.of(2, reference), SumTail.of(3, reference))
        threshold = float(tails[1].threshold(config.scan_pfa / count))
        bearings.setflags(write=False)
        return cls(plan, bearings, independent, threshold, c, config, tails)

    @property
    def tolerance_cells(self) -> int:
        """The tolerance in envelope cells (at least 1)."""
        return max(1, int(math.ceil(self.config.tolerance_s * self.plan.sample_rate_hz / self.plan.decimation)))

    def seed_threshold(self, span_s: ArrayLike) -> NDArray[np.float64]:
        """The seeded family's threshold on the two other channels' sum, for seeds whose echoes
        claim ``span_s`` (s) of their channel (elementwise)."""
        tau_c = float(self.plan.correlation_time_s)
        spans = np.asarray(span_s, dtype=float)
        count = effective_hypotheses(spans, tau_c, self.independent_bearings, self.config.tolerance_s, 2)
        return self.tails[0].threshold(self.config.seed_pfa / count)


__all__ = ("JointDetection", "JointSearchConfig", "JointSetup", "echo_cells", "effective_hypotheses",
           "joint_search", "local_noise", "main_lobe_half_angle_rad", "SumTail")
