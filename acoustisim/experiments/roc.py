"""Scoring detections against the simulator's truth, and ROC curves (a helper of ``clutter``; no ``NAME``).

A *target* is one object's echo on one channel of one ping: the object's first-order
(specular or edge-diffracted) arrivals there. It is detected at a score threshold s when an
echo with score >= s lies within the tolerance of one of them; its *best score* is the highest
such echo's score (-inf when none). An echo is *explained* when it lies within the tolerance
of an arrival of any kind (tank multipaths, reverberation) and the noise-free record's envelope
reaches ``explained_fraction`` x the noise standard deviation within that tolerance (the
reverberation of 2000 diffuse rays puts an arrival every few microseconds, so closeness alone
would explain every noise peak); an unexplained echo is a *false alarm*. Sweeping s post hoc
gives the ROC: P_D(s) = fraction of targets with best score >= s, and false alarms per ping
FA(s) = unexplained echoes with score >= s / pings. Both fall as s rises: the curve is
monotone by construction.

Elastic echoes (``/truth/internal_arrivals``, :mod:`acoustisim.propagation.elastic_echoes`): an
echo that is no target's but lies within the tolerance of an internal arrival of an elastic
echo (the compressional echo through a post's diameter, 42 us after it; a pipe's wall
reverberations), with the noise-free envelope above the noise there, is *elastic*: a real echo
the truth explains (not a false alarm), but one that no object is at: a false target if a
localiser takes it for one. Internal arrivals within the tolerance of their own echo are that
echo (unresolved from it).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray


def first_order_targets(arrivals: NDArray[Any], surface_names: Sequence[str], object_names: Sequence[str],
                        window_s: tuple[float, float]) -> list[tuple[int, str, NDArray[np.float64]]]:
    """The targets of one ping: (channel, object name, delays (s) of its first-order arrivals).

    Only objects whose earliest first-order arrival on the channel lies inside ``window_s``.
    """
    from acoustisim.propagation.paths import PathKind

    names = np.asarray(list(surface_names) + [""], dtype=object)
    ids = arrivals["object_ids"]
    first = names[np.where(ids[:, 0] < 0, len(surface_names), ids[:, 0])]
    single = (ids[:, 1] < 0) if ids.shape[1] > 1 else np.ones(len(arrivals), dtype=bool)
    kinds = (arrivals["kind"] == int(PathKind.SPECULAR)) | (arrivals["kind"] == int(PathKind.EDGE))
    targets = []
    for ch in range(3):
        for name in object_names:
            sel = (arrivals["channel"] == ch) & single & kinds & (first == name)
            delays = np.sort(arrivals["delay_s"][sel])
            if delays.size and window_s[0] <= delays[0] <= window_s[1]:
                targets.append((ch, name, delays))
    return targets


def echo_arrival(arrivals: NDArray[Any], channel: int, tof_s: float, tolerance_s: float) -> int | None:
    """Row of the strongest (non-direct) arrival on ``channel`` within ``tolerance_s`` of an echo's TOF (None: none)."""
    near = np.flatnonzero((arrivals["channel"] == channel) & (np.abs(arrivals["delay_s"] - tof_s) <= tolerance_s)
                          & (arrivals["kind"] != 0))
    if near.size == 0:
        return None
    return int(near[int(np.argmax(np.abs(arrivals["amplitude"][near])))])


def arrival_object(arrivals: NDArray[Any], row: int | None, surface_names: Sequence[str],
                   object_names: Sequence[str]) -> str | None:
    """The first scene object on an arrival's path (None: no row, or a path of tank boundaries only)."""
    if row is None:
        return None
    objects = set(object_names)
    for i in arrivals["object_ids"][row]:
        if i >= 0 and surface_names[i] in objects:
            return str(surface_names[i])
    return None


def elastic_object(internal: NDArray[Any] | None, channel: int, tof_s: float, tolerance_s: float) -> int | None:
    """The surface index of the elastic object whose resolved internal arrival lies within
    ``tolerance_s`` of an echo on ``channel`` (the strongest by level; None: none)."""
    if internal is None or internal.size == 0:
        return None
    near = internal[(internal["channel"] == channel) & (np.abs(internal["delay_s"] - tof_s) <= tolerance_s)
                    & (internal["after_echo_s"] > tolerance_s)]
    if near.size == 0:
        return None
    return int(near["object_id"][int(np.argmax(near["level_db"]))])


def score_echoes(echoes: Sequence[Sequence[Any]], targets: list[tuple[int, str, NDArray[np.float64]]],
                 arrivals: NDArray[Any], clean_envelope: NDArray[np.float64], t0_s: float, sample_rate_hz: float,
                 noise_sigma_v: NDArray[np.float64], tolerance_s: float,
                 explained_fraction: float = 1.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Best score of every target and the scores of the false alarms, for one ping
    (:func:`score_echoes_elastic` without internal arrivals)."""
    best, fa, _ = score_echoes_elastic(echoes, targets, arrivals, clean_envelope, t0_s, sample_rate_hz,
                                       noise_sigma_v, tolerance_s, explained_fraction)
    return best, fa


def score_echoes_elastic(echoes: Sequence[Sequence[Any]], targets: list[tuple[int, str, NDArray[np.float64]]],
                         arrivals: NDArray[Any], clean_envelope: NDArray[np.float64], t0_s: float,
                         sample_rate_hz: float, noise_sigma_v: NDArray[np.float64], tolerance_s: float,
                         explained_fraction: float = 1.0, internal: NDArray[Any] | None = None
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Best score of every target, the scores of the false alarms and of the elastic echoes, for one ping.

    Parameters
    ----------
    echoes : sequence (3 channels) of sequence of Echo
    targets : from ``first_order_targets``
    arrivals : the ping's arrivals (``Paths.arrivals()``)
    clean_envelope : ndarray, shape (3, n)
        Envelope of the noise-free record (V), sample 0 at ``t0_s``.
    t0_s, sample_rate_hz : float
    noise_sigma_v : ndarray, shape (3,)
        Noise standard deviation per channel (V).
    tolerance_s : float
    explained_fraction : float
        An echo is explained only where the clean envelope reaches this x sigma.
    internal : structured ndarray, optional
        The ping's internal arrivals (``INTERNAL_ARRIVAL_DTYPE``).

    Returns
    -------
    target_best : ndarray, shape (len(targets),)
        -inf for a target no echo matches.
    false_alarm_scores : ndarray
    elastic_scores : ndarray
        Echoes explained by an internal arrival of an elastic echo (and no target).
    """
    best = np.full(len(targets), -np.inf)
    fa: list[float] = []
    elastic: list[float] = []
    n = clean_envelope.shape[1]
    half = int(np.ceil(tolerance_s * sample_rate_hz))
    for ch in range(3):
        on_ch = arrivals["delay_s"][(arrivals["channel"] == ch) & (arrivals["kind"] != 0)]
        for e in echoes[ch]:
            hit = False
            for k, (tch, _, delays) in enumerate(targets):
                if tch == ch and np.any(np.abs(delays - e.tof_s) <= tolerance_s):
                    best[k] = max(best[k], e.score)
                    hit = True
            if hit:
                continue
            i = int(round((e.tof_s - t0_s) * sample_rate_hz))
            lo, hi = max(0, i - half), min(n, i + half + 1)
            strong = hi > lo and float(np.max(clean_envelope[ch, lo:hi])) >= explained_fraction * noise_sigma_v[ch]
            if strong and elastic_object(internal, ch, e.tof_s, tolerance_s) is not None:
                elastic.append(e.score)
                continue
            near = bool(np.any(np.abs(on_ch - e.tof_s) <= tolerance_s))
            if not (strong and near):
                fa.append(e.score)
    return best, np.asarray(fa, dtype=float), np.asarray(elastic, dtype=float)


def roc_curve(target_best: NDArray[np.float64], false_alarm_scores: NDArray[np.float64], n_pings: int,
              n_points: int = 200) -> dict[str, list[float]]:
    """P_D and false alarms per ping against the score threshold (ascending thresholds).

    Parameters
    ----------
    target_best : ndarray
        Best score per target (-inf: never detected).
    false_alarm_scores : ndarray
    n_pings : int
    n_points : int
        Thresholds: quantiles of all finite scores (scores themselves; at most this many), plus 0.

    Returns
    -------
    dict
        ``threshold``, ``pd``, ``fa_per_ping`` (lists; pd and fa non-increasing).
    """
    scores = np.concatenate([target_best[np.isfinite(target_best)], false_alarm_scores])
    if scores.size:
        quantiles = np.quantile(scores, np.linspace(0, 1, n_points), method="inverted_cdf")
        thresholds = np.unique(np.concatenate([[0.0], quantiles]))
    else:
        thresholds = np.array([0.0])
    tb = np.sort(target_best)
    fs = np.sort(false_alarm_scores)
    n_t = max(1, tb.size)
    pd = (tb.size - np.searchsorted(tb, thresholds, side="left")) / n_t
    fa = (fs.size - np.searchsorted(fs, thresholds, side="left")) / max(1, n_pings)
    return {"threshold": thresholds.tolist(), "pd": pd.tolist(), "fa_per_ping": fa.tolist()}
