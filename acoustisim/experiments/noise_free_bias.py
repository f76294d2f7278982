"""The bias of each detector at a sweep position, split by the mechanisms that cause it.

Every repeat of a position has the same echo and only new noise, so the error splits into a
bias, the same in every repeat, and a scatter. The bias is measured directly by running each
detector on the noise-free averaged record (``Simulation.clean``), picking per channel the
detected echo nearest the true time of flight, and decomposed by re-synthesising the noise-free
record from subsets of the paths (``edge_scene.NOISE_FREE_PARTS``): the edge's diffraction alone
(the beam's effect on the extended edge's echo), plus the specular paths (walls, floor,
surface), plus the diffuse reverberation (everything).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from acoustisim.experiments.edge_scene import NOISE_FREE_PARTS, Position, path_subsets
from acoustisim.experiments.gating import gate_recording
from acoustisim.experiments.sweep_detectors import (
    BEAM_MATCHED,
    beam_matched_echoes,
    estimate_point,
    nearest_echoes,
)


def noise_free_records(position: Position, paths: Any, synthesiser: Any, clean_all: Any) -> dict[str, Any]:
    """The noise-free record (3, n) of each of ``NOISE_FREE_PARTS``: the edge alone, plus the
    specular paths, everything (``clean_all``, the simulation's own noise-free record)."""
    from acoustisim.simulation import simulate

    masks = path_subsets(paths)
    records: dict[str, Any] = {}
    for part in NOISE_FREE_PARTS:
        if part == "all":
            records[part] = clean_all
            continue
        subset = paths.select(masks[part])  # keeps the rows' transfer functions (Paths.responses)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
            records[part] = simulate(position.scene, position.sonar, paths=subset, seed=0, n_pings=1,
                                     synthesiser=synthesiser).clean
    return records


def noise_free_errors(recording: Any, clean: Any, detectors: tuple[str, ...], truth_tof_s: Any, truth: Any,
                      sound_speed_m_s: float, half_baseline_m: float, gate: tuple[float, float],
                      transducers: Any = None) -> dict[str, Any]:
    """Errors of each detector (except the threshold detector, whose threshold needs noise) on a noise-free record.

    ``BEAM_MATCHED`` refines the matched filter's echoes nearest the truth with ``transducers``
    (``sweep_detectors.recording_array``).

    Parameters
    ----------
    recording : Recording
        The simulated recording (its sampling, template and channel positions are kept).
    clean : ndarray, shape (3, n)
        The noise-free record that replaces its waveforms.
    detectors : tuple of str
    truth_tof_s : sequence of 3 float
    truth : ObjectTruth
        ``range_m`` and ``bearing_deg``, the errors' reference.
    sound_speed_m_s, half_baseline_m : float
    gate : (start_s, stop_s)

    Returns
    -------
    dict
        Per detector: ``tof_error_s`` (left, right; NaN when the edge's echo is not detected),
        ``range_error_m``, ``bearing_error_deg``.
    """
    from binsonar.detection import detect

    record = gate_recording(replace(recording, waveforms=np.asarray(clean, dtype=float)[np.newaxis]), *gate)
    out: dict[str, Any] = {}
    for method in detectors:
        if method == "threshold":
            continue
        if method == BEAM_MATCHED:
            echoes = nearest_echoes(detect(record, "matched"), truth_tof_s)
            if echoes[0] is not None and echoes[2] is not None:
                echoes = beam_matched_echoes(record, echoes, transducers, sound_speed_m_s)
        else:
            echoes = nearest_echoes(detect(record, method), truth_tof_s)
        r, b = estimate_point(echoes, sound_speed_m_s, half_baseline_m)
        out[method] = {"tof_error_s": [float("nan") if e is None else e.tof_s - truth_tof_s[ch]
                                       for ch, e in ((0, echoes[0]), (2, echoes[2]))],
                       "range_error_m": r - truth.range_m, "bearing_error_deg": b - truth.bearing_deg}
    return out
