"""Echo detectors and time-of-flight estimators.

``detect(data, method, ...)`` runs any of ``METHODS`` on a ``Recording`` or an array and
returns a ``DetectionResult``. Importing this package loads numpy only; each method imports
scipy / PyWavelets when it runs.
"""

from binsonar.detection.api import BASE_METHODS, METHODS, detect, method_options
from binsonar.detection.echo import DetectionResult, Echo

__all__ = ["BASE_METHODS", "METHODS", "DetectionResult", "Echo", "detect", "method_options"]
