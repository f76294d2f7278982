"""Echo detectors and time-of-flight estimators.

``detect(data, method, ...)`` runs any of ``METHODS`` on a ``Recording`` or an array and
returns a ``DetectionResult``; ``prepare(method, ...)`` sets a method up once for a template
and record length, and its ``run(data)`` then processes each new ping (live use); ``Detector().detect(data, method, ...)`` is ``detect`` planning each set-up once
(a live loop that does not hold the prepared detectors itself). Importing this package loads numpy only; each method imports
scipy / PyWavelets when it runs.
"""

from binsonar.detection.api import BASE_METHODS, METHODS, PreparedDetector, detect, method_options, prepare
from binsonar.detection.detector import Detector
from binsonar.detection.echo import DetectionResult, Echo

__all__ = (
    "BASE_METHODS",
    "METHODS",
    "DetectionResult",
    "Detector",
    "Echo",
    "PreparedDetector",
    "detect",
    "method_options",
    "prepare",
)
