"""``Detector``: ``detect`` for a live loop of pings, planning each method once.

``detect(data, method, ...)`` plans the method on every call: the matched filter's template
spectrum and analytic template, the local matched filter's tone table and short-FFT weights,
the threshold factors. A ``Detector`` keeps the prepared detectors (``api.PreparedDetector``) it builds, keyed on
the method, the template (its bytes), the sample rate, the record length and the options, in
a small least-recently-used store owned by the object (no module-level state), so that a loop
over pings with the same set-up pays the planning once and each call costs what
``prepare(...).run(ping)`` costs plus the key (``DetectionSettings.plan_key``: the template's
bytes hashed).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, Callable, Hashable

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.api import PreparedDetector, detect_with_settings
from binsonar.detection.echo import DetectionResult
from binsonar.detection.settings import DetectionSettings
from binsonar.recording import Recording, RecordingError


class Detector:
    """``detect`` with a bounded store of prepared detectors (see the module notes).

    Parameters
    ----------
    max_plans : int
        Prepared detectors kept (the least recently used is dropped beyond it); each holds a
        method's plan, up to a few MB for the record-size matched filter.

    Examples
    --------
    >>> detector = Detector()
    >>> for ping in pings:  # doctest: +SKIP
    ...     result = detector.detect(ping, "local-matched", sample_rate_hz=20e6, template=pulse)
    """

    def __init__(self, max_plans: int = 8) -> None:
        if not (isinstance(max_plans, (int, np.integer)) and max_plans >= 1):
            raise RecordingError(f"max_plans must be an integer >= 1, got {max_plans!r}")
        self._max_plans = int(max_plans)
        self._plans: OrderedDict[Hashable, PreparedDetector] = OrderedDict()
        self.builds = 0
        """Prepared detectors built so far (cache misses)."""

    def __len__(self) -> int:
        """Prepared detectors held."""
        return len(self._plans)

    def prepared(self, key: Hashable, build: Callable[[], PreparedDetector]) -> PreparedDetector:
        """The prepared detector stored under ``key``, or ``build()``'s, stored (``api.PlanStore``)."""
        found = self._plans.get(key)
        if found is not None:
            self._plans.move_to_end(key)
            return found
        built = build()
        self.builds += 1
        self._plans[key] = built
        if len(self._plans) > self._max_plans:
            self._plans.popitem(last=False)
        return built

    def detect(self, data: Recording | NDArray[np.floating], method: str, **arguments: Any) -> DetectionResult:
        """``binsonar.detection.detect(data, method, **arguments)``, planned once per set-up.

        Raises
        ------
        RecordingError
            As ``detect``.
        """
        return detect_with_settings(data, method, DetectionSettings.from_arguments(arguments), self)
