"""Simulate pings of a scene: propagation -> synthesis -> a recording with ground truth.

``simulate`` is the one call that ties the packages together: it traces the paths
(``acoustisim.propagation.solve``) unless given, synthesises ``n_pings`` digitised pings
(``acoustisim.synthesis``) and packs them in a ``binsonar.recording.Recording`` whose template
is the transmitted pulse through the receive chain. ``write_simulation`` stores it with the
ground truth under ``/truth``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.preflight import check_simulation
from acoustisim.propagation.paths import Paths, PathKind
from acoustisim.scene import Scene
from acoustisim.sonar import CHANNEL_NAMES, SonarHead
from acoustisim.synthesis.chain import ReceiverChain
from acoustisim.synthesis.pings import PingSynthesiser
from binsonar.array_description import ArrayDescription, ChannelDescription, ElectricalChain, PistonDirectivity
from binsonar.recording import Recording, Template, write_recording

if TYPE_CHECKING:
    from acoustisim.propagation.config import SolverConfig

CREATED_BY = "acoustisim simulate"
"""``created_by`` of simulated recordings (fixed, so that files are byte-identical)."""

OBJECT_CLASSES: Mapping[str, str] = {
    "edge": "point",
    "post": "cylinder",
    "cylinder": "cylinder",
    "sphere": "cylinder",
    "plate": "plane",
}
"""Localisation class of each object kind (binsonar's "point", "cylinder", "plane", "unknown"):
a sphere, like a post, is a circle of known radius in the horizontal plane."""


@dataclass(frozen=True, eq=False)
class Simulation:
    """The result of :func:`simulate`.

    Attributes
    ----------
    recording : binsonar.recording.Recording
        Volts, (n_pings, 3, n_samples) (one averaged ping when ``average``), with template,
        environment and pose.
    codes : int16 ndarray, shape (n_pings, 3, n_samples), or None
        The ADC codes (None for an averaged recording, stored as float volts).
    paths : Paths
        Every traced path.
    clean : ndarray, shape (3, n_samples)
        Noise-free ADC input (V): echoes and main bang after the chain.
    truth : mapping
        Datasets/attributes for ``/truth``: ``arrivals`` (structured array, one row per
        arrival), ``surface_names``, ``objects`` (JSON), ``scene_toml`` (when available),
        ``internal_arrivals`` (when an elastic object's echo rings: one row per named internal
        arrival of each such echo).
    noise_sigma_v : ndarray (3,) or None
        White-noise standard deviation per channel (V) set by ``snr_db``.
    """

    recording: Recording
    codes: NDArray[np.int16] | None = field(repr=False)
    paths: Paths = field(repr=False)
    clean: NDArray[np.float64] = field(repr=False)
    truth: Mapping[str, Any] = field(repr=False)
    noise_sigma_v: NDArray[np.float64] | None = None


def echo_rows(
    paths: Paths, echo: str | int | None, n_boundaries: int, record_s: float | None = None
) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]]:
    """The rows of one named echo on each channel (left, centre, right).

    Parameters
    ----------
    paths : Paths
    echo : str, int or None
        None: the strongest target echo on each channel (a specular or edge arrival that touches
        only scene objects, no tank boundary) that arrives within ``record_s``. A surface name:
        the strongest arrival on each channel whose every interaction is on that surface. An
        int: that ``path_id``.
    n_boundaries : int
        Number of tank boundaries (they come first in ``paths.surface_names``).
    record_s : float, optional
        The record's length (s): with ``echo`` None, later echoes are not candidates.

    Raises
    ------
    InputError
        The echo does not exist on some channel.
    """
    arrivals = paths.arrivals()
    ids = arrivals["object_ids"].astype(np.int64)
    touched = ids >= 0
    kind = arrivals["kind"]
    if echo is None:
        mask = np.isin(kind, (PathKind.SPECULAR, PathKind.EDGE)) & touched.any(axis=1)
        mask &= np.all(~touched | (ids >= n_boundaries), axis=1)
        if record_s is not None:
            mask &= arrivals["delay_s"] < record_s
        label = "the strongest target echo"
    elif isinstance(echo, (int, np.integer)) and not isinstance(echo, bool):
        mask = arrivals["path_id"] == int(echo)
        label = f"path_id {int(echo)}"
    elif isinstance(echo, str):
        if echo not in paths.surface_names:
            known = ", ".join(paths.surface_names) or "none"
            raise InputError(f"snr_echo = {echo!r}: no surface of that name (known: {known})")
        index = paths.surface_names.index(echo)
        mask = (kind != PathKind.DIRECT) & touched.any(axis=1) & np.all(~touched | (ids == index), axis=1)
        label = f"echo {echo!r}"
    else:
        raise InputError(f"snr_echo must be a surface name, a path_id or None, got {echo!r}")
    selected = []
    for channel in range(3):
        candidates = arrivals[mask & (arrivals["channel"] == channel)]
        if candidates.size == 0:
            raise InputError(f"snr_echo: {label} does not exist on channel {CHANNEL_NAMES[channel]}")
        best = candidates[int(np.argmax(np.abs(candidates["amplitude"])))]
        rows = paths.rows
        selected.append(rows[(rows["path_id"] == best["path_id"]) & (rows["channel"] == channel)])
    return selected[0], selected[1], selected[2]


def objects_json(scene: Scene) -> str:
    """The scene's objects as a JSON list: name, kind, material, position_m, radius_m, size_m, class."""
    items = []
    for obj in scene.objects:
        bounds = obj.bounds_m
        position = None
        radius = None
        if obj.primitive is not None:
            position = getattr(obj.primitive, "center_m", None)
            radius = getattr(obj.primitive, "radius_m", None)
        for key in ("center_m", "edge_m", "position_m"):
            if position is None and obj.parameter(key) is not None:
                position = obj.parameter(key)
        if position is None:
            position = 0.5 * (bounds[0] + bounds[1])
        if radius is None and obj.parameter("radius_m") is not None:
            radius = obj.parameter("radius_m")
        items.append(
            {
                "name": obj.name,
                "kind": obj.kind,
                "material": obj.material.name,
                "position_m": [float(v) for v in np.ravel(position)],
                "radius_m": None if radius is None else float(radius),
                "size_m": [float(v) for v in bounds[1] - bounds[0]],
                "class": OBJECT_CLASSES.get(obj.kind, "unknown"),
            }
        )
    return json.dumps(items, sort_keys=True)


def _scene_toml(scene: Scene) -> str | None:
    try:
        from scenes.scene_file import scene_to_toml
    except ImportError:
        return None
    return scene_to_toml(scene)


def truth_of(scene: Scene, paths: Paths) -> dict[str, Any]:
    """The ground truth written under ``/truth``: ``arrivals``, ``surface_names``, ``objects``,
    ``scene_toml`` and, when echoes of elastic objects ring, ``internal_arrivals``
    (:func:`acoustisim.propagation.elastic_echoes.internal_arrival_table`)."""
    import h5py

    from acoustisim.propagation.elastic_echoes import internal_arrival_table

    truth: dict[str, Any] = {
        "arrivals": paths.arrivals(),
        "surface_names": np.array(paths.surface_names, dtype=h5py.string_dtype()),
        "objects": objects_json(scene),
    }
    internal = internal_arrival_table(paths)
    if internal.size:
        truth["internal_arrivals"] = internal
    toml = _scene_toml(scene)
    if toml is not None:
        truth["scene_toml"] = toml
    return truth


SIMULATED_ROLES: Mapping[str, str] = MappingProxyType({"transmit-receive": "both", "receive": "receive",
                                                      "transmit": "transmit"})
"""The array description's role of each of the simulator's transducer roles."""


def array_description_of(sonar: SonarHead, chain: ReceiverChain, volts_per_code: float | None) -> ArrayDescription:
    """The array description of a simulated head (written as every recording's ``/array``).

    Each transducer's role, face centre and axis (head frame), its piston diameter, and its
    receive chain: the net gain (gain minus attenuation, dB; a time-varying gain is not part of
    it), the receive sensitivity, and the ADC step and resolution.
    """
    channels = []
    for index, transducer in enumerate(sonar.transducers):
        electrical = ElectricalChain(
            gain_db=float(chain.gain_db[index] - chain.attenuation_db[index]),
            receive_sensitivity_db=float(chain.receive_sensitivity_db),
            volts_per_code=volts_per_code,
            adc_bits=int(sonar.adc_bits),
        )
        channels.append(ChannelDescription(transducer.name, SIMULATED_ROLES[transducer.role], transducer.position_head_m,
                                           transducer.axis_head, PistonDirectivity(2.0 * transducer.radius_m),
                                           electrical))
    return ArrayDescription(tuple(channels), float(sonar.sample_rate_hz))


def _check_synthesiser(
    synthesiser: PingSynthesiser, sonar: SonarHead, scene: Scene, chain: ReceiverChain | None
) -> None:
    """Raise InputError unless ``synthesiser`` was planned for this sonar (any pose), medium, chain."""
    planned = synthesiser.sonar.with_pose(sonar.position_m, sonar.yaw_deg, sonar.pitch_deg, sonar.roll_deg)
    if planned != sonar or synthesiser.sonar.custom_pulse is not sonar.custom_pulse:
        raise InputError("synthesiser: planned for another sonar (pulse, transducers or digitiser differ)")
    if synthesiser.medium != scene.medium:
        raise InputError("synthesiser: planned for another medium")
    if chain is not None and synthesiser.chain != chain:
        raise InputError("synthesiser: planned for another receiver chain")


def simulate(
    scene: Scene,
    sonar: SonarHead | None = None,
    *,
    solver_config: "SolverConfig | None" = None,
    chain: ReceiverChain | None = None,
    seed: int = 0,
    n_pings: int = 1,
    snr_db: float | None = None,
    snr_echo: str | int | None = None,
    average: bool = False,
    paths: Paths | None = None,
    synthesiser: PingSynthesiser | None = None,
) -> Simulation:
    """Simulate ``n_pings`` pings of a scene as the seed's hardware would record them.

    Parameters
    ----------
    scene : Scene
    sonar : SonarHead, optional
        Sonar and pose (default ``scene.sonar``).
    solver_config : SolverConfig, optional
        Propagation settings (default ``SolverConfig()``).
    chain : ReceiverChain, optional
        Receiver settings (default ``ReceiverChain()``).
    seed : int
        Noise seed (>= 0); ping i uses ``SeedSequence(seed).spawn(n_pings)[i]``.
    n_pings : int
        Pings with independent noise (same paths).
    snr_db : float, optional
        Set 2E/N0 of ``snr_echo`` on each channel with white noise (replaces the noise models).
    snr_echo : str or int, optional
        A surface name or a path_id; default the strongest target echo within the record.
    average : bool
        Store the mean of the digitised pings as one float ping.
    paths : Paths, optional
        Already traced paths (skips the propagation solver).
    synthesiser : PingSynthesiser, optional
        A synthesiser planned earlier (``PingSynthesiser.create``) for the same sonar (any pose),
        medium and chain: skips the planning (the pulse's spectra and tables, the chain's
        filters) when simulating many poses.

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Bad parameters (the message names the field and the value).
    """
    check_simulation(scene, sonar, solver_config, chain=chain, n_pings=n_pings, snr_db=snr_db, solving=paths is None)
    sonar = scene.sonar if sonar is None else sonar
    if snr_db is not None and not (isinstance(snr_db, (int, float, np.floating)) and np.isfinite(snr_db)):
        raise InputError(f"snr_db must be a finite number, got {snr_db!r}")
    if paths is None:
        from acoustisim.propagation import solve

        paths = solve(scene, sonar, solver_config)
    if synthesiser is None:
        synthesiser = PingSynthesiser.create(sonar, scene.medium, chain)
    else:
        _check_synthesiser(synthesiser, sonar, scene, chain)
    snr_rows = None
    if snr_db is not None:
        snr_rows = echo_rows(paths, snr_echo, len(scene.boundaries), float(sonar.record_length_s))
    pings = synthesiser.render(paths.rows, seed=seed, n_pings=n_pings, snr_db=snr_db, snr_rows=snr_rows,
                               responses=paths.responses)
    samples, t0 = synthesiser.template()
    template = Template(samples, sonar.sample_rate_hz, t0, "transmitted-pulse")
    pose = np.array([*sonar.position_m, sonar.yaw_deg, sonar.pitch_deg, sonar.roll_deg], dtype=float)
    if average:
        waveforms = pings.volts.mean(axis=0, keepdims=True)
        clipped = pings.clipped.any(axis=0, keepdims=True)
        codes = None
    else:
        waveforms, clipped, codes = pings.volts, pings.clipped, pings.codes
    recording = Recording(
        waveforms=waveforms,
        sample_rate_hz=float(sonar.sample_rate_hz),
        t0_s=0.0,
        channel_positions_m=sonar.channel_positions_head,
        clipped=clipped,
        template=template,
        sound_speed_m_s=float(scene.medium.sound_speed),
        temperature_c=float(scene.medium.temperature_c),
        pose=np.broadcast_to(pose, (waveforms.shape[0], 6)),
        volts_per_code=None if average else pings.volts_per_code,
        adc_bits=int(sonar.adc_bits),
        created_by=CREATED_BY,
        array=array_description_of(sonar, synthesiser.chain, pings.volts_per_code),
    )
    return Simulation(recording, codes, paths, pings.clean, truth_of(scene, paths), pings.noise_sigma_v)


def write_simulation(path: str | os.PathLike[str], sim: Simulation) -> Path:
    """Write a simulation's recording and ground truth (atomic, byte-deterministic)."""
    return write_recording(path, sim.recording, codes=sim.codes, truth=sim.truth)
