"""Synthetic datasets at scale: a TOML spec of a scene distribution, drawn sample by sample
from per-sample seeds, simulated on Dask, written to a resumable Zarr store.

- :mod:`~acoustisim.datasets.spec`: the spec file (:func:`load_spec`, :class:`SpecError`).
- :mod:`~acoustisim.datasets.sampling`: drawing sample i (scene, pose, SNR) and placements.
- :mod:`~acoustisim.datasets.store`: the Zarr layout, atomic per-sample writes, completion.
- :mod:`~acoustisim.datasets.generate`: :func:`generate` (LocalCluster, scheduler or in-process).
- :mod:`~acoustisim.datasets.verify`, :mod:`~acoustisim.datasets.info`: checks and summaries.
- :mod:`~acoustisim.datasets.loader`: :func:`open_dataset` (xarray, complete samples only),
  numpy batches and a torch-free map-style dataset.

Dask, Zarr and tqdm are imported only by the functions that use them.
"""

from typing import Any

from acoustisim.datasets.spec import DatasetSpec, SpecError, load_spec, loads_spec

__all__ = ("DatasetSpec", "SpecError", "load_spec", "loads_spec", "open_dataset")


def open_dataset(path: Any) -> Any:
    """The complete samples of a dataset store as an ``xarray.Dataset`` (see
    :func:`acoustisim.datasets.loader.open_dataset`)."""
    from acoustisim.datasets.loader import open_dataset as open_complete

    return open_complete(path)
