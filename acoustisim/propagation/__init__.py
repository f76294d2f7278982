"""Propagation engine: every transmitter-to-receiver path through a scene.

``solve(scene, sonar=None, config=None) -> Paths``; ``prepare(scene)`` does the per-scene work
once for many poses. Submodules are imported lazily by the solver where they need SciPy.
"""

from acoustisim.propagation.config import MECHANISMS, SolverConfig
from acoustisim.propagation.paths import PATH_DTYPE, PathKind, Paths
from acoustisim.propagation.prepared import PreparedScene, prepare
from acoustisim.propagation.solver import solve

__all__ = ["MECHANISMS", "PATH_DTYPE", "PathKind", "Paths", "PreparedScene", "SolverConfig", "prepare", "solve"]
