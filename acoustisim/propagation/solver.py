"""``solve(scene, sonar, config) -> Paths``: every path from the transmitter to each receiver.

Mechanisms run in order, each given a :class:`SolveContext` whose ``first_path_id`` is the next
free id: direct, specular (:mod:`.specular`), then edge diffraction
(:func:`~acoustisim.propagation.edges.edge_paths`, on the prepared scene's sharp edges,
extracted once) and diffuse reverberation (:func:`~acoustisim.propagation.diffuse.diffuse_paths`),
each when named in ``config.mechanisms``. :func:`~acoustisim.propagation.columns.complete_columns` then fills the derived
columns of every row and the amplitude floor (:func:`floor_mask`, judged across the pulse band)
culls weak arrivals.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.propagation.columns import complete_columns
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.diffuse import diffuse_paths
from acoustisim.propagation.edges import edge_paths
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import PATH_DTYPE, PathKind, Paths, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene, prepare
from acoustisim.propagation.specular import direct_rows, specular_rows
from acoustisim.scene import Scene
from acoustisim.sonar import CHANNEL_NAMES, SonarHead

def check_sonar(prepared: PreparedScene, sonar: SonarHead) -> None:
    """Raise :class:`InputError` if a transducer touches or is inside a surface, or a receive-only
    transducer sits on the transmitter.

    "Touching" is closer than the piston radius a to a tank boundary or an object surface: the
    face of the piston would cut the surface.
    """
    scene = prepared.scene
    a = float(sonar.piston_radius_m)
    tx = np.asarray(sonar.transmitter_position, dtype=float)
    positions = np.asarray(sonar.receiver_positions, dtype=float)
    for i, name in enumerate(CHANNEL_NAMES):
        if i != 1 and np.linalg.norm(positions[i] - tx) < a:
            raise InputError(
                f"sonar: the {name} receiver at {positions[i].round(4).tolist()} m coincides with the transmitter "
                f"at {tx.round(4).tolist()} m (closer than the piston radius {a} m)"
            )
    if scene.tank is not None:
        inside = scene.tank.contains(positions, margin_m=a)
        if not np.all(inside):
            i = int(np.argmin(inside))
            raise InputError(
                f"sonar.position_m: the {CHANNEL_NAMES[i]} transducer at {positions[i].round(4).tolist()} m is "
                f"outside the water or within {a} m of a tank boundary"
            )
    for obj, (lo, hi) in zip(scene.objects, prepared.object_bounds):
        near = np.all((positions >= lo - a) & (positions <= hi + a), axis=1)
        if not np.any(near):
            continue
        candidates = positions[near]
        primitive = obj.primitive
        if isinstance(primitive, SpherePrimitive):
            distance = np.linalg.norm(candidates - np.asarray(primitive.center_m), axis=1) - primitive.radius_m
        elif isinstance(primitive, CylinderPrimitive):
            local = candidates - np.asarray(primitive.center_m)
            along = local @ np.asarray(primitive.axis)
            radial = np.linalg.norm(local - np.outer(along, primitive.axis), axis=1) - primitive.radius_m
            axial = np.abs(along) - 0.5 * primitive.length_m
            outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
            distance = np.where((radial < 0) & (axial < 0), np.maximum(radial, axial), outside)
        else:
            import trimesh

            # trimesh's sign convention: positive inside
            distance = -trimesh.proximity.signed_distance(obj.mesh, candidates)
        if np.any(distance < a):
            i = int(np.flatnonzero(near)[int(np.argmin(distance))])
            raise InputError(
                f"sonar.position_m: the {CHANNEL_NAMES[i]} transducer at {positions[i].round(4).tolist()} m touches "
                f"or is inside object {obj.name!r} (closer than the piston radius {a} m)"
            )


FLOOR_BAND_DB = -20.0
"""Default judging band of the amplitude floor: where the pulse spectrum is within this of its
peak (dB)."""

FLOOR_BAND_FREQUENCIES = 7
"""Frequencies, evenly spread over the band (plus the centre frequency), at which the floor
judges an arrival's level."""


def pulse_band_hz(sonar: SonarHead, level_db: float = FLOOR_BAND_DB) -> tuple[float, float]:
    """(lowest, highest) frequency (Hz) where the sonar's pulse spectrum |Q(f)| is within
    ``level_db`` of its peak, on a grid of step f0 / 1000 over (0, 4 f0] (the seed's 5 us Gaussian
    pulse at 500 kHz: about 141-859 kHz at -20 dB)."""
    f0 = float(sonar.centre_frequency_hz)
    grid = np.linspace(0.0, 4.0 * f0, 4001)[1:]
    magnitude = np.abs(sonar.pulse.spectrum(grid))
    inside = np.flatnonzero(magnitude >= magnitude.max() * 10.0 ** (level_db / 20.0))
    return float(grid[inside[0]]), float(grid[inside[-1]])


def floor_frequencies(context: SolveContext, band_hz: tuple[float, float] | None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The frequencies (Hz, shape (m,)) at which the amplitude floor judges levels, and the
    pulse's relative spectrum |Q(f)| / max |Q| at them (shape (m,)).

    :data:`FLOOR_BAND_FREQUENCIES` evenly spaced over ``band_hz`` (None: :func:`pulse_band_hz`)
    plus the centre frequency.
    """
    low, high = pulse_band_hz(context.sonar) if band_hz is None else band_hz
    frequencies = np.unique(np.r_[np.linspace(low, high, FLOOR_BAND_FREQUENCIES), context.centre_frequency_hz])
    magnitude = np.abs(context.sonar.pulse.spectrum(frequencies))
    peak = max(float(magnitude.max()), float(np.abs(context.sonar.pulse.spectrum(context.centre_frequency_hz))))
    return frequencies, magnitude / peak if peak > 0 else np.ones_like(magnitude)


def band_levels(rows: NDArray[Any], group: NDArray[np.intp], n_groups: int, context: SolveContext,
                frequencies_hz: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each arrival's strongest level across the band: max over f of
    w(f) |sum over its rows of g D_tx(f) D_rx(f) 10^(-alpha(f) L / 20) exp(j (phase - 2 pi f dtau))|
    (dtau: delay relative to any one row of the arrival).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        With the derived angles filled (:func:`complete_columns`).
    group : ndarray of int, shape (n,)
        The arrival (0 .. n_groups - 1) of each row: edge elements of one (path_id, channel)
        add up coherently, with their delays dtau relative to the group's first row.
    n_groups : int
    context : SolveContext
    frequencies_hz, weights : ndarray, shape (m,)
        From :func:`floor_frequencies`.

    Returns
    -------
    ndarray, shape (n_groups,)
        Levels (Pa per Pa at 1 m, the ``amplitude`` column's unit, weighted by the pulse's
        relative spectrum).
    """
    if rows.size == 0:
        return np.zeros(n_groups)
    c, a = context.sound_speed_m_s, context.piston_radius_m
    f = frequencies_hz[None, :]
    alpha = np.asarray(context.scene.medium.absorption_db_per_m(frequencies_hz), dtype=float)[None, :]
    factor = (rows["geometric_gain"][:, None] * piston_directivity(rows["angle_tx_rad"][:, None], f, a, c)
              * piston_directivity(rows["angle_rx_rad"][:, None], f, a, c)
              * 10.0 ** (-alpha * rows["path_length_m"][:, None] / 20.0))
    if n_groups == rows.size and np.array_equal(group, np.arange(n_groups)):
        return np.max(np.abs(factor) * weights, axis=1)
    # delays relative to one row of each group (the magnitude does not depend on which)
    reference = np.empty(n_groups)
    reference[group[::-1]] = rows["delay_s"][::-1]
    phase = rows["phase_rad"][:, None] - 2.0 * np.pi * f * (rows["delay_s"] - reference[group])[:, None]
    total = np.empty((n_groups, frequencies_hz.size), dtype=complex)
    for j in range(frequencies_hz.size):  # a few band frequencies, each a vectorised sum over rows
        total[:, j] = np.bincount(group, factor[:, j] * np.cos(phase[:, j]), n_groups) + 1j * np.bincount(
            group, factor[:, j] * np.sin(phase[:, j]), n_groups)
    return np.max(np.abs(total) * weights, axis=1)


def directivity_envelope(highest_hz: float, context: SolveContext
                         ) -> Callable[[NDArray[np.float64], ArrayLike], NDArray[np.float64]]:
    """A function ``bound(angle_rad, frequency_hz)`` (broadcast) giving an upper bound of
    |D(angle, f')| for every f' in [frequency_hz, highest_hz] (D the piston directivity,
    :func:`piston_directivity`).

    For x = k a sin(angle), max over those f' of |2 J1(x') / x'| <= sup over x' >= x of
    |2 J1(x') / x'| (x at ``frequency_hz``): a non-increasing function of x, tabulated on a
    grid of step h as the reverse running maximum, read at the grid point at or below x, plus
    h / 4 (|d/dx 2 J1(x)/x| = |2 J2(x)/x| < 1/4, so no peak between grid points is missed).
    0 behind the piston.
    """
    from scipy.special import j1

    c, a = context.sound_speed_m_s, context.piston_radius_m
    x_max = 2.0 * np.pi * highest_hz / c * a
    grid = np.linspace(0.0, x_max, 4097)
    safe = np.where(grid > 0, grid, 1.0)
    magnitude = np.where(grid > 0, np.abs(2.0 * j1(safe) / safe), 1.0)
    envelope = np.minimum(np.maximum.accumulate(magnitude[::-1])[::-1] + 0.25 * grid[1], 1.0)

    def bound(angle_rad: NDArray[np.float64], frequency_hz: ArrayLike) -> NDArray[np.float64]:
        scale = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) / c * a / grid[1]
        x = scale * np.sin(np.minimum(angle_rad, 0.5 * np.pi))
        index = np.minimum(x.astype(np.intp), grid.size - 1)
        return np.where(angle_rad <= 0.5 * np.pi, envelope[index], 0.0)

    return bound


def floor_mask(rows: NDArray[Any], floor_db: float | None, context: SolveContext,
               band_hz: tuple[float, float] | None = None) -> NDArray[np.bool_]:
    """Which rows survive the amplitude floor (whole arrivals are kept or dropped).

    An arrival (a row, or the rows of an edge diffraction sharing ``path_id`` and channel) is
    dropped when its strongest level across the band (:func:`band_levels`) is below
    ``floor_db`` relative to the strongest such level of any non-direct arrival; direct paths
    are always kept. Judging across the band, not at the centre frequency alone, keeps an
    echo that sits near the pistons' first null at f0 (about 11 deg off axis for the seed's
    19 mm, 500 kHz pistons) but is strong at the band's lower frequencies.

    The band levels are computed only where needed: each arrival's level lies between its
    level at the centre frequency (one of the band frequencies; from the ``amplitude``-side
    columns, no Bessel function) and an upper bound (the sum of |g| times the directivity
    envelopes, :func:`directivity_envelope`, times the absorption at the band's lowest
    frequency; pulse weights <= 1); most arrivals fall clearly on one side of the threshold.
    Single rows left undecided are evaluated one band frequency at a time, highest pulse
    weight first, and leave as soon as they reach the threshold.

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        With the derived columns filled.
    floor_db : float or None
        None keeps every row.
    context : SolveContext
    band_hz : (float, float) or None
        ``SolverConfig.amplitude_floor_band_hz``.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    keep = np.ones(rows.size, dtype=bool)
    if floor_db is None or rows.size == 0:
        return keep
    frequencies, weights = floor_frequencies(context, band_hz)
    low, high = float(frequencies[0]), float(frequencies[-1])
    centre_weight = float(weights[np.searchsorted(frequencies, context.centre_frequency_hz)])
    alpha_min = float(np.min(context.scene.medium.absorption_db_per_m(frequencies)))
    kind = rows["kind"]
    edge = np.flatnonzero(kind == int(PathKind.EDGE))
    single = np.flatnonzero((kind != int(PathKind.EDGE)) & (kind != int(PathKind.DIRECT)))
    n_single = single.size

    envelope = directivity_envelope(high, context)
    # every row's upper bound, from the strided fields in place (cheaper than gathering them)
    upper_rows = np.abs(rows["geometric_gain"])
    upper_rows *= envelope(rows["angle_tx_rad"], low)
    upper_rows *= envelope(rows["angle_rx_rad"], low)
    upper_rows *= 10.0 ** (-alpha_min * rows["path_length_m"] / 20.0)

    # edge arrivals: groups of rows; the centre-frequency level is the coherent sum there
    keys = rows["path_id"][edge].astype(np.int64) * 8 + rows["channel"][edge]
    unique_keys, group = np.unique(keys, return_inverse=True)
    group = group.ravel()
    n_groups = unique_keys.size
    edge_rows = np.take(rows, edge)  # np.take gathers records faster than fancy indexing
    reference = np.empty(n_groups)
    reference[group[::-1]] = edge_rows["delay_s"][::-1]  # the first row's (any row would do)
    centre_factor = (edge_rows["geometric_gain"] * edge_rows["directivity_tx"] * edge_rows["directivity_rx"]
                     * 10.0 ** (-edge_rows["absorption_db"] / 20.0))
    phase = edge_rows["phase_rad"] - 2.0 * np.pi * context.centre_frequency_hz * (edge_rows["delay_s"] - reference[group])
    centre_level = np.hypot(np.bincount(group, centre_factor * np.cos(phase), n_groups),
                            np.bincount(group, centre_factor * np.sin(phase), n_groups))
    lower = np.concatenate([rows["amplitude"][single], centre_level]) * centre_weight
    upper = np.concatenate([upper_rows[single], np.bincount(group, upper_rows[edge], n_groups)])

    alpha = np.asarray(context.scene.medium.absorption_db_per_m(frequencies), dtype=float)

    c, a = context.sound_speed_m_s, context.piston_radius_m

    def reaches(picked: NDArray[np.intp], threshold: float) -> NDArray[np.bool_]:
        """Whether single rows ``picked`` reach ``threshold`` at some band frequency: the
        :func:`band_levels` test, one frequency at a time (highest pulse weight first) over
        the rows not yet above it."""
        result = np.zeros(picked.size, dtype=bool)
        remaining = np.arange(picked.size)
        gain, angle_tx = rows["geometric_gain"][picked], rows["angle_tx_rad"][picked]
        angle_rx, length = rows["angle_rx_rad"][picked], rows["path_length_m"][picked]
        for j in np.argsort(-weights, kind="stable"):  # a few frequencies, each vectorised over rows
            if remaining.size == 0:
                break
            f = frequencies[j]
            # the same operations, in the same order, as band_levels
            factor = (gain[remaining] * piston_directivity(angle_tx[remaining], f, a, c)
                      * piston_directivity(angle_rx[remaining], f, a, c)
                      * 10.0 ** (-alpha[j] * length[remaining] / 20.0))
            above = np.abs(factor) * weights[j] >= threshold
            result[remaining[above]] = True
            remaining = remaining[~above]
        return result

    def exact(arrivals: NDArray[np.intp]) -> NDArray[np.float64]:
        """Band levels of arrivals (indices into ``lower``: singles, then edge groups)."""
        levels = np.empty(arrivals.size)
        is_single = arrivals < n_single
        picked = single[arrivals[is_single]]
        levels[is_single] = band_levels(np.take(rows, picked), np.arange(picked.size), picked.size, context, frequencies,
                                        weights)
        groups = arrivals[~is_single] - n_single
        if groups.size:
            renumber = np.full(n_groups, -1, dtype=np.intp)
            renumber[groups] = np.arange(groups.size)
            members = np.flatnonzero(renumber[group] >= 0)
            levels[~is_single] = band_levels(np.take(edge_rows, members), renumber[group[members]], groups.size, context,
                                             frequencies, weights)
        return levels

    known = float(lower.max(initial=0.0))
    contenders = np.flatnonzero(upper >= known)
    strongest = max(known, float(exact(contenders).max(initial=0.0)))
    threshold = strongest * 10.0 ** (floor_db / 20.0)
    verdict = lower >= threshold
    undecided = np.flatnonzero(~verdict & (upper >= threshold))
    single_undecided = undecided[undecided < n_single]
    verdict[single_undecided] = reaches(single[single_undecided], threshold)
    groups_undecided = undecided[undecided >= n_single]
    verdict[groups_undecided] = exact(groups_undecided) >= threshold
    keep[single] = verdict[:n_single]
    keep[edge] = verdict[n_single:][group]
    return keep


def solve(scene: Scene | PreparedScene, sonar: SonarHead | None = None,
          config: SolverConfig | None = None) -> Paths:
    """Every transmitter-to-receiver path of ``scene`` for one sonar pose.

    Parameters
    ----------
    scene : Scene or PreparedScene
        A prepared scene (:func:`acoustisim.propagation.prepared.prepare`) skips the per-scene
        work (mesh checks, Embree build), for many poses of one scene.
    sonar : SonarHead, optional
        The pose; defaults to ``scene.sonar``.
    config : SolverConfig, optional
        Defaults to ``SolverConfig()``.

    Returns
    -------
    Paths
        Rows sorted by channel then delay.

    Raises
    ------
    InputError
        Degenerate meshes, a transducer touching a surface or coincident with the transmitter.
    """
    config = SolverConfig() if config is None else config
    if not isinstance(config, SolverConfig):
        raise InputError(f"solver config must be a SolverConfig, got {type(config).__name__}")
    prepared = prepare(scene)
    sonar = prepared.scene.sonar if sonar is None else sonar
    check_sonar(prepared, sonar)
    context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
    parts: list[NDArray[Any]] = []
    next_id = 0

    def add(rows: NDArray[Any]) -> None:
        nonlocal next_id
        rows = np.asarray(rows, dtype=PATH_DTYPE)
        parts.append(rows)
        if rows.size:
            next_id = max(next_id, int(rows["path_id"].max()) + 1)

    if "direct" in config.mechanisms:
        add(direct_rows(context.with_first_path_id(next_id)))
    if "specular" in config.mechanisms:
        add(specular_rows(context.with_first_path_id(next_id), prepared, config.max_order))
    if "edge" in config.mechanisms:
        add(edge_paths(context.with_first_path_id(next_id), config, prepared.sharp_edges))
    if "diffuse" in config.mechanisms:
        add(diffuse_paths(context.with_first_path_id(next_id), config, threads=config.threads,
                          visibility=config.diffuse_visibility))
    # joined as raw records (np.concatenate of a structured dtype copies field by field)
    records = np.dtype((np.void, PATH_DTYPE.itemsize))
    rows = np.concatenate([part.view(records) for part in parts]).view(PATH_DTYPE) if parts else empty_paths_array(0)
    rows = complete_columns(rows, context)
    keep = floor_mask(rows, config.amplitude_floor_db, context, config.amplitude_floor_band_hz)
    if not keep.all():
        rows = np.take(rows, np.flatnonzero(keep))
    # np.take gathers whole records several times faster than fancy indexing of a structured array
    rows = np.take(rows, np.lexsort((rows["delay_s"], rows["channel"])))
    return Paths.adopt(rows, prepared.scene.surface_names, context.centre_frequency_hz, context.sound_speed_m_s)


__all__ = ["FLOOR_BAND_DB", "FLOOR_BAND_FREQUENCIES", "band_levels", "check_sonar", "directivity_envelope",
           "floor_frequencies",
           "floor_mask", "pulse_band_hz", "solve"]
