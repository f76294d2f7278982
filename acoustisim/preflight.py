"""The pre-flight: one check, before any work, that a simulation can run and fits the machine.

``acoustisim scene validate``, ``simulate``, ``demo``, ``dataset generate`` and the Python API
(:func:`acoustisim.simulation.simulate` and :func:`acoustisim.propagation.solve` call it first)
all go through :func:`preflight`, so they accept and refuse the same things with the same
one-line messages.

What it checks
--------------
1. Types: a :class:`~acoustisim.scene.Scene`, a :class:`~acoustisim.sonar.SonarHead`, a
   ``SolverConfig``, an integer number of pings, a finite SNR (``InputTypeError`` otherwise).
   Values, finiteness and physical ranges of each descriptor are checked when it is built
   (:mod:`acoustisim.ranges`), so a ``Scene`` that exists holds legal values.
2. Consistency of the signal (:func:`check_sampling`): the sample rate carries the pulse's
   band (twice its -40 dB top) and the receiver chain's band-pass; the record holds the pulse.
   The message names the key at fault: a carrier above the Nyquist frequency blames
   ``sonar.centre_frequency_hz``, a band too wide for the rate names the rate and the pulse.
3. Resources (:mod:`acoustisim.resources`): triangles, diffuse ray-bounces, specular
   reflector sequences and memory (recording, synthesis, path table, meshes) against the
   limits in force; the refusal states the estimate, the limit and how to raise it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from acoustisim import checks, ranges
from acoustisim.errors import InputError, ResourceLimitError
from acoustisim.resources import (
    ENVIRONMENT,
    FLAGS,
    GIB,
    ResourceEstimate,
    ResourceLimits,
    SceneMeasures,
    combined,
    current_limits,
    geometry_estimate,
    signal_estimate,
)
from acoustisim.scene import Scene
from acoustisim.sonar import SonarHead

if TYPE_CHECKING:
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.synthesis.chain import ReceiverChain

BAND_LEVEL_DB = -40.0
"""The pulse's band ends where its spectrum falls this far below its peak (dB)."""


def _raise_hint(name: str, flags: bool) -> str:
    return f"raise it with {FLAGS[name]} or {ENVIRONMENT[name]}" if flags else f"raise it with {ENVIRONMENT[name]}"


def check_types(scene: Any, sonar: Any = None, config: Any = None) -> tuple[Scene, SonarHead, "SolverConfig"]:
    """The scene (or a prepared scene's), the sonar (default the scene's) and the solver
    configuration (default ``SolverConfig()``), after checking their types.

    Raises
    ------
    InputTypeError
    """
    from acoustisim.propagation.config import SolverConfig

    inner = getattr(scene, "scene", None)
    if not isinstance(scene, Scene) and isinstance(inner, Scene):  # a PreparedScene
        scene = inner
    checks.instance("", "scene", scene, Scene, "a Scene (see scenes.load_scene)")
    sonar = scene.sonar if sonar is None else sonar
    checks.instance("", "sonar", sonar, SonarHead, "a SonarHead or None")
    config = SolverConfig() if config is None else config
    checks.instance("", "solver_config", config, SolverConfig, "a SolverConfig or None")
    return scene, sonar, config


def check_sampling(sonar: SonarHead, chain: "ReceiverChain | None" = None, source: str = "") -> None:
    """The sample rate carries the pulse and the receiver's band-pass; the record holds the pulse.

    Raises
    ------
    InputError
        The message names the key at fault (``sonar.centre_frequency_hz``, ``sonar.sample_rate_hz``
        or ``sonar.record_length_s``) and the values it depends on.
    """
    from acoustisim.synthesis.chain import ReceiverChain
    from acoustisim.synthesis.transducer import pulse_band_top_hz

    prefix = f"{source}: " if source else ""
    fs = float(sonar.sample_rate_hz)
    pulse = sonar.pulse
    if sonar.custom_pulse is None and sonar.centre_frequency_hz >= fs / 2.0:
        raise InputError(
            f"{prefix}sonar.centre_frequency_hz = {sonar.centre_frequency_hz:g}: at or above half the sample rate"
            f" (sonar.sample_rate_hz = {fs:g} Hz); the pulse cannot be sampled")
    band_top = pulse_band_top_hz(pulse, BAND_LEVEL_DB)
    corner = (chain if chain is not None else ReceiverChain()).bandpass_high_hz
    needed = max(2.0 * band_top, 0.0 if corner is None else 2.0 * corner)
    if fs <= needed:
        if sonar.custom_pulse is not None:
            made_of = "the custom pulse"
        else:
            made_of = (f"sonar.centre_frequency_hz = {sonar.centre_frequency_hz:g} Hz,"
                       f" sonar.pulse_duration_s = {sonar.pulse_duration_s:g} s")
        raise InputError(
            f"{prefix}sonar.sample_rate_hz = {fs:g} must exceed {needed:g} Hz: twice the top of the pulse's band"
            f" ({band_top:g} Hz, from {made_of}) and of the receiver's band-pass ({corner or 0.0:g} Hz)")
    start, stop = pulse.support_s
    pulse_length = float(stop - start)
    record = float(sonar.record_length_s)
    if record < pulse_length or sonar.n_samples < 2:
        raise InputError(
            f"{prefix}sonar.record_length_s = {record:g}: shorter than the transmitted pulse ({pulse_length:g} s"
            + ("" if sonar.custom_pulse is not None else f", from sonar.pulse_duration_s = {sonar.pulse_duration_s:g}")
            + f") or than two samples at sonar.sample_rate_hz = {fs:g} Hz; the record cannot hold an echo")


def _memory_message(estimate: ResourceEstimate, sonar: SonarHead, pings_key: str) -> str:
    signal = estimate.recording_bytes + estimate.synthesis_bytes
    parts = [
        (signal, f"the recording and its synthesis {signal / GIB:.3g} GiB: {pings_key} = {estimate.n_pings} ping(s)"
                 f" x 3 channels x {estimate.n_samples:,} samples (sonar.sample_rate_hz = {sonar.sample_rate_hz:g}"
                 f" x sonar.record_length_s = {sonar.record_length_s:g})"),
        (estimate.path_table_bytes, f"the path table {estimate.path_table_bytes / GIB:.3g} GiB"
                                    f" ({estimate.path_rows:,} rows at most)"),
        (estimate.mesh_bytes, f"the meshes {estimate.mesh_bytes / GIB:.3g} GiB ({estimate.triangles:,} triangles)"),
    ]
    parts.sort(key=lambda item: -item[0])
    return "; ".join(text for _, text in parts)


def check_resources(estimate: ResourceEstimate, limits: ResourceLimits, sonar: SonarHead, *, source: str = "",
                    pings_key: str = "n_pings", order_key: str = "max_order", flags: bool = True) -> None:
    """Compare an estimate with the limits.

    ``flags``: name the command-line options that raise each limit besides its environment
    variable (False for ``dataset generate``, whose workers read only the environment).

    Raises
    ------
    ResourceLimitError
        The first limit exceeded, with the estimate, the limit and how to raise it.
    """
    prefix = f"{source}: " if source else ""
    if estimate.objects > limits.max_objects:
        raise ResourceLimitError(
            f"{prefix}{estimate.objects:,} objects, more than the limit of {limits.max_objects:,.0f}"
            f" ({_raise_hint('max_objects', flags)})")
    if estimate.triangles > limits.max_triangles:
        raise ResourceLimitError(
            f"{prefix}the objects have {estimate.triangles:,} triangles, more than the limit of"
            f" {limits.max_triangles:,.0f} ({_raise_hint('max_triangles', flags)})")
    if estimate.rays > limits.max_rays:
        raise ResourceLimitError(
            f"{prefix}solver diffuse_rays x diffuse_bounces = {estimate.rays:,} ray-bounces, more than the limit of"
            f" {limits.max_rays:,.0f} ({_raise_hint('max_rays', flags)})")
    if estimate.chains > limits.max_chains:
        raise ResourceLimitError(
            f"{prefix}up to {estimate.chains:.3g} specular reflector sequences ({estimate.reflectors:,} reflecting"
            f" surfaces, {order_key} = {estimate.max_order}), more than the limit of {limits.max_chains:.3g}"
            f" ({_raise_hint('max_chains', flags)}, or lower {order_key})")
    limit_bytes = limits.max_memory_gb * GIB
    if estimate.memory_bytes > limit_bytes:
        raise ResourceLimitError(
            f"{prefix}needs about {estimate.memory_bytes / GIB:.3g} GiB of memory"
            f" ({_memory_message(estimate, sonar, pings_key)}), more than the limit of {limits.max_memory_gb:g} GiB"
            f" ({_raise_hint('max_memory_gb', flags)})")


def check_run_options(n_pings: Any, snr_db: Any, *, pings_key: str = "n_pings", snr_key: str = "snr_db") -> int:
    """The number of pings (an integer >= 1) after checking it, and the SNR (None or in range).

    Raises
    ------
    InputTypeError, InputError
    """
    pings = checks.integer("", pings_key, n_pings, minimum=1)
    if snr_db is not None:
        checks.real("", snr_key, snr_db, ranges.SNR_DB)
    return pings


def preflight(
    scene: Any,
    sonar: Any = None,
    config: Any = None,
    *,
    n_pings: Any = 1,
    snr_db: Any = None,
    chain: "ReceiverChain | None" = None,
    limits: ResourceLimits | None = None,
    solving: bool = True,
    synthesis: bool = True,
    source: str = "",
    pings_key: str = "n_pings",
    order_key: str = "max_order",
) -> ResourceEstimate:
    """Check that ``n_pings`` pings of ``scene`` can be simulated within the limits.

    Parameters
    ----------
    scene : Scene or PreparedScene
    sonar : SonarHead, optional
        Default ``scene.sonar``.
    config : SolverConfig, optional
        Default ``SolverConfig()``.
    n_pings : int
    snr_db : float, optional
    chain : ReceiverChain, optional
        The receiver chain whose band-pass the sample rate must carry (default ``ReceiverChain()``).
    limits : ResourceLimits, optional
        Default :func:`acoustisim.resources.current_limits`.
    solving : bool
        Count the propagation solver's needs (False when the paths are already traced).
    synthesis : bool
        Count the synthesis's needs and check the sampling (False for a solve alone).
    source : str
        What messages name first (the scene file); default the scene's name.
    pings_key, order_key : str
        How messages name the number of pings and the reflection order (``--pings``, ``--max-order``
        on the command line).

    Returns
    -------
    ResourceEstimate

    Raises
    ------
    InputTypeError
        An argument of the wrong type.
    InputError
        A signal that cannot be sampled or recorded.
    ResourceLimitError
        More than the limits allow.
    """
    measures = prepared_measures(scene)
    scene, sonar, config = check_types(scene, sonar, config)
    where = source or scene.name
    pings = check_run_options(n_pings, snr_db, pings_key=pings_key)
    limits = current_limits() if limits is None else checks.instance("", "limits", limits, ResourceLimits,
                                                                     "ResourceLimits or None")
    if synthesis:
        check_sampling(sonar, chain, where)
    signal = signal_estimate(sonar, pings) if synthesis else ResourceEstimate()
    geometry = ResourceEstimate()
    if solving:
        measures = SceneMeasures(scene) if measures is None else measures
        # counts first: they bound the per-mesh work of the full estimate
        check_resources(ResourceEstimate(objects=measures.objects, triangles=measures.triangles), limits, sonar,
                        source=where)
        geometry = geometry_estimate(scene, config, measures)
    estimate = combined(signal, geometry) if synthesis else geometry  # (a solve has no signal part)
    check_resources(estimate, limits, sonar, source=where, pings_key=pings_key, order_key=order_key)
    return estimate


def prepared_measures(scene: Any) -> SceneMeasures | None:
    """The :class:`~acoustisim.resources.SceneMeasures` a prepared scene keeps (computed once for
    every pose it is solved at), or None for anything else."""
    from acoustisim.propagation.prepared import PreparedScene

    return scene.resource_measures if isinstance(scene, PreparedScene) else None


def check_solve(scene: Any, sonar: Any = None, config: Any = None) -> None:
    """The pre-flight of :func:`acoustisim.propagation.solve` (geometry only, current limits)."""
    preflight(scene, sonar, config, synthesis=False)


def check_simulation(scene: Any, sonar: Any = None, config: Any = None, *, chain: Any = None, n_pings: Any = 1,
                     snr_db: Any = None, solving: bool = True) -> None:
    """The pre-flight of :func:`acoustisim.simulation.simulate` (current limits)."""
    preflight(scene, sonar, config, chain=chain, n_pings=n_pings, snr_db=snr_db, solving=solving)


__all__ = ("check_resources", "check_run_options", "check_sampling", "check_simulation", "check_solve",
           "check_types", "preflight", "prepared_measures")
