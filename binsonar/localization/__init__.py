"""Localisation: from echoes' times of flight to classified targets with covariances.

Point targets (exact seed-geometry range and bearing, general weighted least squares), cylinders
(the seed's tri-aural approximation and the exact bistatic circle), planes, classification by
residuals against the expected noise, association of echoes, multi-pose fusion and the
``localize`` pipeline. Works on bistatic path lengths (c x TOF); scipy is imported only when a
fit runs.
"""

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.association import Association, associate
from binsonar.localization.circle import circle_path_lengths, fit_circle, tri_aural_approximation
from binsonar.localization.classify import classify
from binsonar.localization.estimate import EstimationConfig, target_from_path_lengths
from binsonar.localization.fit import ModelFit
from binsonar.localization.frames import head_to_tank, head_to_tank_rotation, tank_to_head
from binsonar.localization.fusion import FusedTarget, PoseObservation, fuse
from binsonar.localization.pipeline import LocalizationConfig, LocalizationError, LocalizationResult, localize
from binsonar.localization.plane import fit_plane, plane_path_lengths
from binsonar.localization.point import (
    fit_point, point_from_path_lengths, point_path_lengths, seed_path_lengths, seed_point_covariance)
from binsonar.localization.target import Target

__all__ = (
    "ArrayGeometry", "Association", "EstimationConfig", "FusedTarget", "LocalizationConfig", "LocalizationError",
    "LocalizationResult", "ModelFit", "PoseObservation", "Target", "associate", "circle_path_lengths", "classify",
    "fit_circle", "fit_plane", "fit_point", "fuse", "head_to_tank", "head_to_tank_rotation", "localize",
    "plane_path_lengths", "point_from_path_lengths", "point_path_lengths", "seed_path_lengths",
    "seed_point_covariance", "tank_to_head", "target_from_path_lengths", "tri_aural_approximation",
)
