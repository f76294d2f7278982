"""Turn one simulated sample into the rows the store holds (waveforms, pose, labels).

The vocabularies (object kinds, classes, materials, arrival kinds, surface names) are fixed
per dataset, so a float code means the same thing in every sample: object ``slot`` k is
named ``object-<k>`` and is surface ``n_boundaries + k``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.datasets.sampling import SampleDescription
from acoustisim.datasets.spec import OBJECT_KINDS, DatasetSpec
from acoustisim.datasets.store import ARRIVAL_FIELDS, OBJECT_FIELDS, SAMPLE_FIELDS, SampleArrays

ARRIVAL_SCALAR_COLUMNS: tuple[str, ...] = (
    "channel", "kind", "order", "delay_s", "path_length_m", "geometric_gain", "phase_rad", "angle_tx_rad",
    "angle_rx_rad", "directivity_tx", "directivity_rx", "absorption_db", "amplitude",
)


@dataclass(frozen=True)
class Vocabularies:
    """The names float codes index, fixed for a dataset."""

    kinds: tuple[str, ...]
    classes: tuple[str, ...]
    materials: tuple[str, ...]
    arrival_kinds: tuple[str, ...]
    surfaces: tuple[str, ...]

    def as_dict(self) -> dict[str, tuple[str, ...]]:
        return {
            "kinds": self.kinds,
            "classes": self.classes,
            "materials": self.materials,
            "arrival_kinds": self.arrival_kinds,
            "surfaces": self.surfaces,
        }


def vocabularies(spec: DatasetSpec) -> Vocabularies:
    """The dataset's vocabularies."""
    from acoustisim.materials import material_library
    from acoustisim.propagation.paths import PathKind
    from acoustisim.scene import Tank

    boundaries = tuple(b.name for b in Tank().boundaries)
    return Vocabularies(
        kinds=tuple(OBJECT_KINDS),
        classes=spec.class_names,
        materials=tuple(sorted(material_library())),
        arrival_kinds=tuple(k.label for k in PathKind),
        surfaces=boundaries + tuple(f"object-{k}" for k in range(spec.max_objects)),
    )


def arrival_rows(arrivals: NDArray[Any], surface_names: tuple[str, ...], vocab: Vocabularies,
                 max_arrivals: int) -> tuple[NDArray[np.float64], int]:
    """The arrivals table as (max_arrivals, len(ARRIVAL_FIELDS)) floats, NaN padded.

    Parameters
    ----------
    arrivals : structured ndarray (n,), ``PATH_DTYPE``
        ``Paths.arrivals()`` (sorted by channel then delay).
    surface_names : tuple of str
        ``Paths.surface_names`` (what ``object_ids`` index).
    vocab : Vocabularies
    max_arrivals : int
        Rows kept; when there are more, the strongest (by ``amplitude``) are kept, in
        channel-then-delay order.

    Returns
    -------
    rows : ndarray (max_arrivals, len(ARRIVAL_FIELDS))
    n_total : int
        Arrivals before truncation.
    """
    n_total = int(arrivals.size)
    if n_total > max_arrivals:
        keep = np.sort(np.argsort(-np.abs(arrivals["amplitude"]), kind="stable")[:max_arrivals])
        arrivals = arrivals[keep]
    n = int(arrivals.size)
    lookup = np.array([vocab.surfaces.index(name) if name in vocab.surfaces else -2 for name in surface_names] + [-1],
                      dtype=float)
    ids = np.asarray(arrivals["object_ids"], dtype=np.int64)
    surfaces = lookup[np.where(ids < 0, len(surface_names), ids)]
    table = np.column_stack(
        [np.asarray(arrivals[c], dtype=float) for c in ARRIVAL_SCALAR_COLUMNS]
        + [np.asarray(arrivals["departure_dir"], float).reshape(n, 3), np.asarray(arrivals["arrival_dir"], float).reshape(n, 3),
           surfaces.reshape(n, 4), np.asarray(arrivals["points_m"], float).reshape(n, 12)]
    ) if n else np.zeros((0, len(ARRIVAL_FIELDS)))
    rows = np.full((max_arrivals, len(ARRIVAL_FIELDS)), np.nan)
    rows[:n] = table
    return rows, n_total


def object_rows(sample: SampleDescription, scene: Any, vocab: Vocabularies, max_objects: int) -> NDArray[np.float64]:
    """The objects table as (max(max_objects, 1), len(OBJECT_FIELDS)) floats, NaN padded.

    Columns: kind/class/material codes; reference point (tank frame, m); axis-aligned size of
    the mesh (m); range (m) and bearing (degrees, positive toward the right receiver) of the
    reference point from the head.
    """
    rows = np.full((max(max_objects, 1), len(OBJECT_FIELDS)), np.nan)
    n = len(sample.objects)
    if n == 0:
        return rows
    reference = np.array([o.reference_m for o in sample.objects], dtype=float)
    bounds = np.array([obj.bounds_m for obj in scene.objects], dtype=float)  # (n, 2, 3)
    head = scene.sonar.tank_to_head(reference)
    rows[:n, 0] = [vocab.kinds.index(o.kind) for o in sample.objects]
    rows[:n, 1] = [vocab.classes.index(o.label) for o in sample.objects]
    rows[:n, 2] = [vocab.materials.index(o.material) for o in sample.objects]
    rows[:n, 3:6] = reference
    rows[:n, 6:9] = bounds[:, 1] - bounds[:, 0]
    rows[:n, 9] = np.linalg.norm(head, axis=1)
    rows[:n, 10] = np.degrees(np.arctan2(head[:, 0], head[:, 1]))
    return rows


def sample_arrays(spec: DatasetSpec, sample: SampleDescription, scene: Any, simulation: Any,
                  vocab: Vocabularies, snr_reference: int) -> SampleArrays:
    """Everything the store keeps of one simulated sample.

    Parameters
    ----------
    spec : DatasetSpec
    sample : SampleDescription
    scene : acoustisim.scene.Scene
        Built from ``sample``.
    simulation : acoustisim.simulation.Simulation
        Its ``codes`` (n_pings, 3, n_time) int16, ``recording`` and ``paths``.
    vocab : Vocabularies
    snr_reference : int
        0: the SNR is set on the strongest target echo; 1: on the strongest echo; -1: not set.
    """
    codes = np.asarray(simulation.codes)
    if codes.dtype != np.int16 or codes.ndim != 3 or codes.shape[:2] != (spec.n_pings, 3):
        raise RuntimeError(f"sample {sample.index}: simulate returned codes {codes.dtype} {codes.shape}, "
                           f"expected int16 ({spec.n_pings}, 3, n_time)")
    recording = simulation.recording
    paths = simulation.paths
    # simulate() already built the arrivals table for its truth: reuse it rather than build it again.
    truth = getattr(simulation, "truth", None)
    arrivals = truth.get("arrivals") if truth is not None else None
    if arrivals is None:
        arrivals = paths.arrivals()
    arrival_table, n_total = arrival_rows(arrivals, tuple(paths.surface_names), vocab, spec.max_arrivals)
    kinds = np.bincount(np.asarray(arrivals["kind"], dtype=np.int64), minlength=4)[:4]
    values = {
        "temperature_c": sample.temperature_c,
        "salinity_ppt": sample.salinity_ppt,
        "sound_speed_m_s": scene.medium.sound_speed,
        "tank_length_m": sample.tank_m[0],
        "tank_width_m": sample.tank_m[1],
        "water_depth_m": sample.tank_m[2],
        "wall_material": vocab.materials.index(sample.wall_material),
        "floor_material": vocab.materials.index(sample.floor_material),
        "snr_db": np.nan if sample.snr_db is None or snr_reference < 0 else sample.snr_db,
        "snr_reference": snr_reference,
        "volts_per_code": np.nan if recording.volts_per_code is None else recording.volts_per_code,
        "t0_s": recording.t0_s,
        "sample_rate_hz": recording.sample_rate_hz,
        "n_objects": len(sample.objects),
        "n_arrivals": min(n_total, spec.max_arrivals),
        "n_arrivals_total": n_total,
        "n_direct": kinds[0],
        "n_specular": kinds[1],
        "n_edge": kinds[2],
        "n_diffuse": kinds[3],
    }
    return SampleArrays(
        index=sample.index,
        waveforms=np.ascontiguousarray(codes),
        pose=np.asarray(sample.pose, dtype=float),
        sample_values=np.array([float(values[k]) for k in SAMPLE_FIELDS]),
        objects=object_rows(sample, scene, vocab, spec.max_objects),
        arrivals=arrival_table,
        scene_json=json.dumps(sample.to_json(), sort_keys=True),
    )
