"""Echo detectors and time-of-flight estimators.

``detect(data, method, ...)`` runs any of ``METHODS`` on a ``Recording`` or an array and
returns a ``DetectionResult``; it is ``prepare(method, ...).run(data)``: ``prepare`` sets a
method up once for a template and record length, and the prepared detector's ``run`` processes
each new ping (live use); ``Detector().detect(data, method, ...)`` is ``detect`` planning each
set-up once (a live loop that does not hold the prepared detectors itself). Each method is one
object of ``methods`` (how it plans, how it runs, what it takes, its options), found by name
in ``registry``. Importing this package loads numpy only; each method imports scipy /
PyWavelets / numba when it runs.
"""

from binsonar.detection.api import PreparedDetector, detect, method_options, prepare
from binsonar.detection.detector import Detector
from binsonar.detection.echo import DetectionResult, Echo
from binsonar.detection.registry import BASE_METHODS, METHODS
from binsonar.detection.settings import DetectionSettings

__all__ = (
    "BASE_METHODS",
    "METHODS",
    "DetectionResult",
    "DetectionSettings",
    "Detector",
    "Echo",
    "PreparedDetector",
    "detect",
    "method_options",
    "prepare",
)
