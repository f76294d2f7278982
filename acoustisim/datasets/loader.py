"""Read a dataset: batches of numpy waveforms and labels, and a PyTorch-style dataset.

Neither imports torch. :class:`WaveformDataset` has ``__len__`` and ``__getitem__`` returning
numpy arrays, which ``torch.utils.data.DataLoader`` accepts as is (its default collate turns
them into tensors).

Only samples recorded complete are served (an interrupted dataset is usable as it stands):
:func:`open_dataset` gives them as an ``xarray.Dataset``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np
from numpy.typing import NDArray

from acoustisim.datasets.store import OBJECT_FIELDS, SAMPLE_FIELDS, DatasetStore, DatasetStoreError


def open_dataset(path: str | Path) -> Any:
    """The store as an ``xarray.Dataset`` of its complete samples only.

    ``xarray.open_zarr(path)`` shows every sample slot of the store: a sample not yet made
    (an interrupted or running generation) holds the arrays' fill values there (waveforms of
    zeros, NaN labels, an empty ``scene_json``) and ``complete == 0``. This function keeps the
    samples whose ``complete`` flag is 1; the ``sample`` coordinate keeps their indices in the
    store. The arrays stay lazy (dask), as ``open_zarr`` gives them.

    Parameters
    ----------
    path : path
        The store directory.

    Returns
    -------
    xarray.Dataset
        Attributes: the root attributes (the dataset card) plus ``n_samples_in_store``.

    Raises
    ------
    DatasetStoreError
        When ``path`` is not a dataset store of this layout.
    """
    import xarray as xr

    store = DatasetStore(path, mode="r")
    complete = store.complete_mask()
    try:
        dataset = xr.open_zarr(str(store.root))
    except Exception as exc:  # noqa: BLE001 - any failure to open is a bad store for the user
        raise DatasetStoreError(f"{store.path}: cannot open with xarray: {exc}") from None
    dataset = dataset.isel(sample=np.flatnonzero(complete))
    dataset.attrs["n_samples_in_store"] = int(complete.size)
    return dataset


class DatasetReader:
    """Random access to the complete samples of a store.

    Parameters
    ----------
    path : path
        The store.
    volts : bool
        Return waveforms as float32 volts (code x volts_per_code) instead of int16 codes.
    """

    def __init__(self, path: str | Path, *, volts: bool = False) -> None:
        self.path = Path(path)
        self.volts = volts
        self._store: DatasetStore | None = None
        self.indices: NDArray[np.int64] = np.flatnonzero(self.store.complete_mask())

    @property
    def store(self) -> DatasetStore:
        """The open store (opened on first use, so that a reader pickles to worker processes)."""
        if self._store is None:
            self._store = DatasetStore(self.path, mode="r")
        return self._store

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_store"] = None
        return state

    def __len__(self) -> int:
        return int(self.indices.size)

    @property
    def vocabularies(self) -> dict[str, list[str]]:
        """Names the float codes index (kinds, classes, materials, arrival_kinds, surfaces)."""
        return dict(self.store.card["vocabularies"])

    def read(self, positions: NDArray[np.int64] | list[int]) -> dict[str, NDArray[Any]]:
        """The samples at these positions (0..len-1 among the complete samples), as a batch.

        Raises
        ------
        DatasetCorruptError
            When a chunk holding one of the samples cannot be decoded (the message names the
            samples and the array, and the commands that find and repair them).

        Returns
        -------
        dict
            ``index`` (B,) sample indices in the store; ``waveforms`` (B, n_pings, 3, n_time)
            int16 codes (float32 volts with ``volts=True``); ``pose`` (B, 6); ``sample_values``
            (B, len(SAMPLE_FIELDS)); ``objects`` (B, max_objects, len(OBJECT_FIELDS));
            ``object_class`` (B, max_objects) int, -1 for empty slots; ``n_objects`` (B,);
            ``arrivals`` (B, max_arrivals, len(ARRIVAL_FIELDS)); ``n_arrivals`` (B,).
        """
        index = self.indices[np.asarray(positions, dtype=np.int64)]
        order = np.argsort(index)
        undo = np.argsort(order)
        sorted_index = index[order]
        s = self.store
        batch = {}
        for name in ("waveforms", "pose", "sample_values", "objects", "arrivals"):
            try:
                batch[name] = np.asarray(s.array(name).oindex[sorted_index])[undo]
            except Exception as exc:  # noqa: BLE001 - a chunk that cannot be decoded is damaged
                raise s.corrupt_error(sorted_index, name, exc) from None
        values = batch["sample_values"]
        if self.volts:
            scale = values[:, SAMPLE_FIELDS.index("volts_per_code")].astype(np.float32)
            batch["waveforms"] = batch["waveforms"].astype(np.float32) * scale[:, None, None, None]
        cls = batch["objects"][:, :, OBJECT_FIELDS.index("class")]
        batch["object_class"] = np.where(np.isfinite(cls), cls, -1).astype(np.int64)
        batch["n_objects"] = values[:, SAMPLE_FIELDS.index("n_objects")].astype(np.int64)
        batch["n_arrivals"] = values[:, SAMPLE_FIELDS.index("n_arrivals")].astype(np.int64)
        batch["index"] = index
        return batch

    def batches(self, batch_size: int, *, shuffle: bool = False, seed: int | None = None,
                drop_last: bool = False) -> Iterator[dict[str, NDArray[Any]]]:
        """Iterate over the complete samples in batches (see :meth:`read` for the keys).

        Parameters
        ----------
        batch_size : int
        shuffle : bool
            Visit the samples in a random order drawn from ``numpy.random.default_rng(seed)``.
        seed : int, optional
        drop_last : bool
            Skip a final short batch.
        """
        if batch_size < 1:
            raise ValueError(f"batch_size = {batch_size}: must be >= 1")
        positions = np.arange(len(self))
        if shuffle:
            positions = np.random.default_rng(seed).permutation(positions)
        for start in range(0, positions.size, batch_size):
            chunk = positions[start : start + batch_size]
            if drop_last and chunk.size < batch_size:
                return
            yield self.read(chunk)


class WaveformDataset:
    """A map-style dataset (``__len__``, ``__getitem__``) for PyTorch and the like, without torch.

    ``dataset[k]`` is ``(waveforms, labels)``: waveforms (n_pings, 3, n_time) float32 volts
    (int16 codes with ``volts=False``), labels a dict of numpy arrays: ``object_class``
    (max_objects,) int64 (-1 empty), ``objects`` (max_objects, len(OBJECT_FIELDS)) float64,
    ``pose`` (6,), ``n_objects`` and ``index`` (0-d int64).

    Parameters
    ----------
    path : path
    volts : bool
    transform : callable, optional
        Applied to the waveforms.
    """

    def __init__(self, path: str | Path, *, volts: bool = True, transform: Any = None) -> None:
        self.reader = DatasetReader(path, volts=volts)
        self.transform = transform

    def __len__(self) -> int:
        return len(self.reader)

    def __getitem__(self, k: int) -> tuple[NDArray[Any], dict[str, NDArray[Any]]]:
        n = len(self)
        if not -n <= k < n:
            raise IndexError(f"index {k} out of range for a dataset of {n} samples")
        batch = self.reader.read([k % n])
        waveforms = batch["waveforms"][0]
        if self.transform is not None:
            waveforms = self.transform(waveforms)
        labels = {
            "object_class": batch["object_class"][0],
            "objects": batch["objects"][0],
            "pose": batch["pose"][0],
            "n_objects": np.int64(batch["n_objects"][0]),
            "index": np.int64(batch["index"][0]),
        }
        return waveforms, labels
