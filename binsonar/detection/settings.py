"""``DetectionSettings``: everything a detection call takes besides the data and the method name."""

from __future__ import annotations

from typing import Any, Hashable, Mapping, NamedTuple

import numpy as np
from numpy.typing import NDArray

from binsonar.recording import Template


class DetectionSettings(NamedTuple):
    """The arguments of ``detect`` (see it for each one's meaning), in one immutable bundle.

    Attributes
    ----------
    sample_rate_hz : float or None
        Arrays only (a recording carries its own).
    t0_s : float
        Arrays only: time of sample 0 after the trigger (s).
    template : Template, array or None
        None: the recording's.
    average : bool or None
        None: the method's own choice (the seed methods').
    bandpass_hz : (low_hz, high_hz), "template" or None
        None: the method's own choice.
    bandpass_order : int
    full_scale_v : float or None
    on_clipped : {"flag", "drop", "error"}
    adc_step_v, volts_per_code : float or None
    adc_bits : int or None
    options : tuple of (name, value)
        The method's options, as given.
    """

    sample_rate_hz: float | None = None
    t0_s: float = 0.0
    template: Template | NDArray[np.floating] | None = None
    average: bool | None = None
    bandpass_hz: tuple[float, float] | str | None = None
    bandpass_order: int = 4
    full_scale_v: float | None = None
    on_clipped: str = "flag"
    adc_step_v: float | None = None
    volts_per_code: float | None = None
    adc_bits: int | None = None
    options: tuple[tuple[str, Any], ...] = ()

    @classmethod
    def from_arguments(cls, arguments: Mapping[str, Any]) -> "DetectionSettings":
        """Keyword arguments as ``detect`` takes them: the fields above by name (``options``
        excepted), every other name a method option."""
        given = {k: v for k, v in arguments.items() if k in ARGUMENT_NAMES}
        return cls(**given, options=tuple((k, v) for k, v in arguments.items() if k not in ARGUMENT_NAMES))

    @property
    def option_dict(self) -> dict[str, Any]:
        """The method options as a dict."""
        return dict(self.options)

    def plan_key(self, method: str, template: Template | NDArray[np.floating] | None, sample_rate_hz: float,
                 n_samples: int) -> Hashable | None:
        """What identifies the prepared detector these settings give for ``method``, ``template``
        (the one that will be used: given or the recording's) and a record's rate and length:
        None when an option cannot be hashed (a list, an array: plan afresh)."""
        key = (method, template_key(template), sample_rate_hz, n_samples, self.average, self.bandpass_hz,
               self.bandpass_order, tuple(sorted(self.options)))
        try:
            hash(key)
        except TypeError:
            return None
        return key


ARGUMENT_NAMES: frozenset[str] = frozenset(DetectionSettings._fields) - {"options"}
"""``detect``'s own keyword arguments (every other keyword is a method option)."""


def template_key(template: Template | NDArray[np.floating] | None) -> Hashable:
    """What identifies a template input: its samples' bytes and, for a ``Template``, its sample
    rate, time origin and kind (an array is taken at the record's rate, part of the plan key)."""
    if template is None:
        return None
    if isinstance(template, Template):
        return (template.samples.tobytes(), template.sample_rate_hz, template.t0_s, template.kind)
    array = np.asarray(template, dtype=float)
    return ("array", array.shape, array.tobytes())
