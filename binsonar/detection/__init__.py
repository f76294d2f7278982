"""Echo detectors and time-of-flight estimators."""

from binsonar.detection.echo import DetectionResult, Echo

__all__ = ["DetectionResult", "Echo"]
