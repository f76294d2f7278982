"""The Zarr layout of a dataset, its chunk writes and its completion records.

Layout version 2 (Zarr v3, one directory; ``xarray.open_zarr(path)`` opens it directly)::

    waveforms      int16   (sample, ping, channel, time)   ADC codes
    pose           float64 (sample, pose_field)            x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg
    sample_values  float64 (sample, sample_field)          medium, tank, SNR, scale, counts
    objects        float64 (sample, object, object_field)  one row per object slot, NaN padded
    arrivals       float64 (sample, arrival, arrival_field) arrivals table, NaN padded
    scene_json     string  (sample,)                       the drawn scene description (JSON)
    checksum       uint64  (sample,)                       CRC-32 and Adler-32 of the sample's stored bytes
    complete       uint8   (sample,)                       1 once every array above holds the sample
    sample, channel, pose_field, sample_field, object_field, arrival_field: coordinates

Every array indexed by ``sample`` is chunked along it by the same ``chunk_samples`` (the
spec's ``samples_per_chunk``; whole along every other axis), so chunk ``k`` of every array
holds samples ``[k * chunk_samples, (k + 1) * chunk_samples)``, and sample ``i`` sits at
row ``i`` of every array: labels line up with waveforms by index. A chunk of samples is the
unit of work: one task simulates its samples and writes, in this order, that chunk of each
data array (together), then its chunk of ``checksum``, then its chunk of ``complete``. A
``LocalStore`` writes each chunk file atomically (temporary ``*.partial`` file, then
rename), so a kill at any moment leaves each chunk file either old or new, and a chunk whose
``complete`` flags are not all 1 is simply redone, identically, on resume. Nobody else
writes these arrays: the workers write their own chunks and the driver only schedules.

Batching samples per chunk divides the fixed cost of a chunk file (opening, encoding and
renaming one file of each of the 8 arrays) by ``chunk_samples``, and the workers' writing their
own completion keeps the driver out of the write path. The price: reading the completion of a
store (resume, ``verify``, ``info``, the loader) reads one small file of ``complete`` per
chunk.

Integer labels are stored as float codes into vocabularies kept in the arrays' attributes
(``objects.attrs["kinds"|"classes"|"materials"]``, ``arrivals.attrs["kinds"|"surfaces"]``,
``sample_values.attrs["materials"]``). The root attributes hold the dataset card
(``attrs["dataset_card"]``): spec, code version, layout version, counts, SNR histogram.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError

LAYOUT_VERSION = 2
"""Version of this layout, stored in the dataset card (``layout_version``); stores of another
version are refused with a message saying so."""

CARD_KEY = "dataset_card"

POSE_FIELDS: tuple[str, ...] = ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")
SAMPLE_FIELDS: tuple[str, ...] = (
    "temperature_c",
    "salinity_ppt",
    "sound_speed_m_s",
    "tank_length_m",
    "tank_width_m",
    "water_depth_m",
    "wall_material",
    "floor_material",
    "snr_db",
    "snr_reference",
    "volts_per_code",
    "t0_s",
    "sample_rate_hz",
    "n_objects",
    "n_arrivals",
    "n_arrivals_total",
    "n_direct",
    "n_specular",
    "n_edge",
    "n_diffuse",
)
OBJECT_FIELDS: tuple[str, ...] = (
    "kind",
    "class",
    "material",
    "x_m",
    "y_m",
    "z_m",
    "size_x_m",
    "size_y_m",
    "size_z_m",
    "range_m",
    "bearing_deg",
)
ARRIVAL_FIELDS: tuple[str, ...] = (
    "channel",
    "kind",
    "order",
    "delay_s",
    "path_length_m",
    "geometric_gain",
    "phase_rad",
    "angle_tx_rad",
    "angle_rx_rad",
    "directivity_tx",
    "directivity_rx",
    "absorption_db",
    "amplitude",
    "departure_dir_x",
    "departure_dir_y",
    "departure_dir_z",
    "arrival_dir_x",
    "arrival_dir_y",
    "arrival_dir_z",
    "surface_0",
    "surface_1",
    "surface_2",
    "surface_3",
    *(f"point_{k}_{axis}" for k in range(4) for axis in "xyz"),
)
SAMPLE_ARRAYS: tuple[str, ...] = ("waveforms", "pose", "sample_values", "objects", "arrivals", "scene_json")
"""Data arrays a task writes for its samples, in checksum order."""


class DatasetStoreError(InputError):
    """A path that is not a usable dataset store (or one made from another spec, or one a
    worker cannot see)."""


class DatasetCorruptError(DatasetStoreError):
    """Stored samples that cannot be read back (a damaged chunk file); the message names the
    store, the samples and the array, and says how to repair them (``problem``: the short
    reason alone)."""

    problem: str = ""


def card_store_id(card: Mapping[str, Any]) -> str:
    """A store's identity from its card: ``store_id`` (stores made before it existed: their
    creation time and name)."""
    return str(card.get("store_id") or f"{card.get('created_utc')}/{card.get('name')}")


def store_seen_here(root: str, store_id: str) -> str:
    """What this process sees at ``root``: "" when it is the store ``store_id``, else the
    reason, one line (run on every Dask worker before any task, see
    :func:`acoustisim.datasets.generate.generate`).

    Reads the root ``zarr.json`` directly (no Zarr import: the check must be cheap).
    """
    try:
        metadata = json.loads(Path(root, "zarr.json").read_text(encoding="utf-8"))
        card = metadata["attributes"][CARD_KEY]
    except (OSError, ValueError, KeyError, TypeError):
        return store_missing_message(root)
    if card_store_id(card) != store_id:
        return (f"{root}: process {os.getpid()} sees another dataset store at this path (store_id "
                f"{card_store_id(card)}, expected {store_id}); every Dask worker must see the same --out")
    return ""


def store_missing_message(root: str | Path) -> str:
    """The one line a process that cannot see a store prints (see :meth:`ChunkWriter.check_visible`)."""
    import socket

    return (f"{root}: no dataset store here as seen by the process {os.getpid()} on host {socket.gethostname()} "
            f"(working directory {os.getcwd()}); every Dask worker must see --out at this same absolute path "
            "(a shared file system)")


@dataclass(frozen=True)
class SampleArrays:
    """The values one sample contributes to every per-sample array (stored dtypes)."""

    index: int
    waveforms: NDArray[np.int16]  # (n_pings, 3, n_time)
    pose: NDArray[np.float64]  # (6,)
    sample_values: NDArray[np.float64]  # (len(SAMPLE_FIELDS),)
    objects: NDArray[np.float64]  # (max_objects, len(OBJECT_FIELDS))
    arrivals: NDArray[np.float64]  # (max_arrivals, len(ARRIVAL_FIELDS))
    scene_json: str

    def checksum(self) -> int:
        """:func:`sample_checksum` of the stored bytes."""
        return sample_checksum(
            {name: getattr(self, name) for name in SAMPLE_ARRAYS}
        )


def sample_checksum(values: Mapping[str, Any]) -> int:
    """A 64-bit checksum of one sample's arrays, as stored: CRC-32 (high 32 bits) and
    Adler-32 (low 32 bits) of their bytes in :data:`SAMPLE_ARRAYS` order.

    It detects corruption (every burst of up to 32 flipped bits; other random damage is
    missed with probability about 2**-64), not deliberate tampering, so a cryptographic hash
    (slower, and guarding against what the store does not defend) is not needed.

    Parameters
    ----------
    values : mapping
        ``SAMPLE_ARRAYS`` names to the sample's arrays (and the JSON string).
    """
    crc, adler = 0, 1
    for name in SAMPLE_ARRAYS:
        value = values[name]
        if name == "scene_json":
            data: Any = str(value).encode("utf-8")
        else:
            data = np.ascontiguousarray(value).reshape(-1).view(np.uint8)  # the bytes, no copy
        crc, adler = zlib.crc32(data, crc), zlib.adler32(data, adler)
    return (crc << 32) | adler


@dataclass(frozen=True)
class StoreShape:
    """The sizes fixed when a store is created."""

    n_samples: int
    n_pings: int
    n_time: int
    max_objects: int
    max_arrivals: int
    chunk_samples: int = 1
    """Samples per chunk along ``sample`` (every array indexed by sample)."""

    def chunk_of(self, index: int) -> tuple[int, int]:
        """``(start, stop)`` of the chunk holding sample ``index``."""
        start = index - index % self.chunk_samples
        return start, min(start + self.chunk_samples, self.n_samples)

    def chunk_starts(self) -> range:
        """First sample of every chunk."""
        return range(0, self.n_samples, self.chunk_samples)


def _zarr():
    import zarr

    return zarr


def create_store(
    path: str | Path,
    shape: StoreShape,
    card: Mapping[str, Any],
    vocabularies: Mapping[str, tuple[str, ...]],
) -> None:
    """Create an empty dataset store (fails if ``path`` exists).

    The store is built in a sibling temporary directory and renamed into place, so a kill
    during creation never leaves a half-made store at ``path``.

    Parameters
    ----------
    path : path
        Directory of the new store.
    shape : StoreShape
    card : mapping
        The initial dataset card (root attribute ``dataset_card``).
    vocabularies : mapping
        ``kinds``, ``classes``, ``materials``, ``arrival_kinds``, ``surfaces``: the names the
        float codes index.
    """
    zarr = _zarr()
    from zarr.codecs import ZstdCodec

    final = Path(path)
    if final.exists():
        raise DatasetStoreError(f"{final}: already exists")
    path = final.parent / f".{final.name}.creating-{uuid.uuid4().hex}"
    group = zarr.open_group(str(path), mode="w-", zarr_format=3)
    n = shape.n_samples
    b = shape.chunk_samples
    if not 1 <= b:
        raise ValueError(f"chunk_samples = {b}: must be >= 1")
    # Zstandard level 1: ~1.6x on noisy 12-bit codes at a tenth of the default level's time.
    fast = (ZstdCodec(level=1),)
    per_sample: dict[str, Any] = dict(fill_value=np.nan, dtype="float64", compressors=fast)

    def coord(name: str, values: tuple[str, ...]) -> None:
        arr = group.create_array(name, shape=(len(values),), dtype=str, dimension_names=(name,))
        arr[:] = np.asarray(values, dtype=object).astype(str)

    group.create_array(
        "waveforms",
        shape=(n, shape.n_pings, 3, shape.n_time),
        chunks=(b, shape.n_pings, 3, shape.n_time),
        dtype="int16",
        fill_value=0,
        compressors=fast,
        dimension_names=("sample", "ping", "channel", "time"),
        attributes={"units": "ADC code", "scale": "volts = code * sample_values[volts_per_code]"},
    )
    group.create_array("pose", shape=(n, len(POSE_FIELDS)), chunks=(b, len(POSE_FIELDS)),
                       dimension_names=("sample", "pose_field"), **per_sample)
    group.create_array("sample_values", shape=(n, len(SAMPLE_FIELDS)), chunks=(b, len(SAMPLE_FIELDS)),
                       dimension_names=("sample", "sample_field"), attributes={"materials": list(vocabularies["materials"])},
                       **per_sample)
    group.create_array(
        "objects",
        shape=(n, max(shape.max_objects, 1), len(OBJECT_FIELDS)),
        chunks=(b, max(shape.max_objects, 1), len(OBJECT_FIELDS)),
        dimension_names=("sample", "object", "object_field"),
        attributes={k: list(vocabularies[k]) for k in ("kinds", "classes", "materials")},
        **per_sample,
    )
    group.create_array(
        "arrivals",
        shape=(n, shape.max_arrivals, len(ARRIVAL_FIELDS)),
        chunks=(b, shape.max_arrivals, len(ARRIVAL_FIELDS)),
        dimension_names=("sample", "arrival", "arrival_field"),
        attributes={
            "kinds": list(vocabularies["arrival_kinds"]),
            "surfaces": list(vocabularies["surfaces"]),
            "channels": ["left", "centre", "right"],
            "order": "by channel then delay; the strongest max_arrivals kept when more",
        },
        **per_sample,
    )
    group.create_array("scene_json", shape=(n,), chunks=(b,), dtype=str, dimension_names=("sample",))
    group.create_array("checksum", shape=(n,), chunks=(b,), dtype="uint64", fill_value=0,
                       dimension_names=("sample",))
    group.create_array("complete", shape=(n,), chunks=(b,), dtype="uint8", fill_value=0,
                       dimension_names=("sample",))
    sample = group.create_array("sample", shape=(n,), chunks=(min(n, 65536),), dtype="int64",
                                dimension_names=("sample",))
    sample[:] = np.arange(n)
    coord("channel", ("left", "centre", "right"))
    coord("pose_field", POSE_FIELDS)
    coord("sample_field", SAMPLE_FIELDS)
    coord("object_field", OBJECT_FIELDS)
    coord("arrival_field", ARRIVAL_FIELDS)
    group.attrs[CARD_KEY] = json.loads(json.dumps({"store_id": uuid.uuid4().hex, **card}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "consolidated metadata is not part of the v3 spec"
        zarr.consolidate_metadata(str(path))
    try:
        os.rename(path, final)
    except OSError as exc:
        shutil.rmtree(path, ignore_errors=True)
        raise DatasetStoreError(f"{final}: cannot create ({exc})") from None


@dataclass(frozen=True)
class ChunkWriter:
    """Picklable handles on the arrays of one store (shipped to each worker once).

    Attributes
    ----------
    arrays : tuple of zarr.Array
        The :data:`SAMPLE_ARRAYS`, then ``checksum``, then ``complete``, opened at the
        store's absolute path (a relative one would be resolved against each worker's own
        working directory).
    shape : StoreShape
    root : str
        Absolute path of the store (checked before every write).
    """

    arrays: tuple[Any, ...]
    shape: StoreShape
    root: str = ""

    def check_visible(self) -> None:
        """Raise :class:`DatasetStoreError` (one line) when this process cannot see the store.

        Zarr would otherwise create the chunk directories wherever the path points in this
        process (a worker on another machine or with another working directory) and the
        samples would never reach the store.
        """
        if not os.path.isfile(os.path.join(self.root, "zarr.json")):
            raise DatasetStoreError(store_missing_message(self.root))

    def read_verified(self, indices: list[int]) -> dict[int, SampleArrays]:
        """The samples among ``indices`` recorded complete whose stored bytes still match their
        recorded checksum, read back as :class:`SampleArrays` (what a chunk rewrite keeps).

        A sample that cannot be read or does not match is left out (it is simulated again).
        """
        if not indices:
            return {}
        checksum, complete = self.arrays[-2], self.arrays[-1]
        kept: dict[int, SampleArrays] = {}
        for index in indices:
            try:
                if not int(complete[index]):
                    continue
                recorded = int(checksum[index])
                values = {name: arr[index] for name, arr in zip(SAMPLE_ARRAYS, self.arrays)}
            except Exception:  # noqa: BLE001 - an unreadable sample is simply made again
                continue
            values = {name: (str(v) if name == "scene_json" else np.asarray(v)) for name, v in values.items()}
            if sample_checksum(values) == recorded:
                kept[index] = SampleArrays(index=index, **values)
        return kept

    def write_chunk(self, samples: list[SampleArrays]) -> NDArray[np.uint64]:
        """Write one whole chunk of samples, then its checksums, then its completion flags.

        The data arrays' chunk files are written together on Zarr's event loop (one round
        trip), each file atomically; ``checksum`` and ``complete`` follow only once they are
        all on disk, so a kill never leaves a sample flagged complete that is not fully
        written.

        Parameters
        ----------
        samples : list of SampleArrays
            Exactly the samples of one chunk, in index order.

        Returns
        -------
        checksums : ndarray (len(samples),) uint64
        """
        import asyncio

        from zarr.core.sync import sync

        if self.root:
            self.check_visible()
        start = samples[0].index if samples else -1
        if not samples or start < 0 or self.shape.chunk_of(start) != (start, start + len(samples)) or [
                s.index for s in samples] != list(range(start, start + len(samples))):
            got = [s.index for s in samples]
            raise ValueError(f"samples {got}: not the whole chunk of {self.shape.chunk_samples} samples "
                             f"starting at a multiple of it (store of {self.shape.n_samples} samples)")
        rows = slice(start, start + len(samples))
        stacked = [
            np.array([s.scene_json for s in samples], dtype=str) if name == "scene_json"
            else np.stack([getattr(s, name) for s in samples])
            for name in SAMPLE_ARRAYS
        ]
        checksums = np.array([s.checksum() for s in samples], dtype=np.uint64)
        data, checksum, complete = self.arrays[:-2], self.arrays[-2], self.arrays[-1]

        async def write_data() -> None:
            await asyncio.gather(*(arr.async_array.setitem(rows, value) for arr, value in zip(data, stacked)))

        sync(write_data())
        checksum[rows] = checksums
        complete[rows] = np.ones(len(samples), dtype=np.uint8)
        return checksums


class DatasetStore:
    """An open dataset store.

    Parameters
    ----------
    path : path
        The store directory.
    mode : {"r", "r+"}
    """

    def __init__(self, path: str | Path, mode: str = "r") -> None:
        zarr = _zarr()
        self.path = Path(path)
        self.root = self.path.expanduser().resolve()
        """Absolute path: what the arrays are opened with, so that they pickle to any process."""
        if not (self.root / "zarr.json").is_file():
            raise DatasetStoreError(f"{self.path}: not a dataset store (no zarr.json)")
        try:
            self.group = zarr.open_group(str(self.root), mode=mode)
        except Exception as exc:  # noqa: BLE001 - any failure to open is a bad path for the user
            raise DatasetStoreError(f"{self.path}: cannot open as a Zarr group: {exc}") from None
        if CARD_KEY not in self.group.attrs:
            raise DatasetStoreError(f"{self.path}: not a dataset store (missing attribute {CARD_KEY!r})")
        version = self.group.attrs[CARD_KEY].get("layout_version")
        if version != LAYOUT_VERSION:
            raise DatasetStoreError(
                f"{self.path}: dataset layout version {version}, this acoustisim reads version {LAYOUT_VERSION} "
                "(chunks of several samples, completion written with each chunk): generate the dataset again "
                "into a new --out")
        missing = [name for name in (*SAMPLE_ARRAYS, "complete", "checksum") if name not in self.group]
        if missing:
            raise DatasetStoreError(f"{self.path}: not a dataset store (missing array {missing[0]!r})")

    @property
    def card(self) -> dict[str, Any]:
        """The dataset card (root attribute)."""
        return dict(self.group.attrs[CARD_KEY])

    def update_card(self, **changes: Any) -> None:
        """Rewrite the card with some keys changed (the root metadata file is replaced atomically)."""
        card = self.card
        card.update(json.loads(json.dumps(changes)))
        self.group.attrs[CARD_KEY] = card

    def array(self, name: str) -> Any:
        """One array of the store."""
        return self.group[name]

    @property
    def n_samples(self) -> int:
        return int(self.group["complete"].shape[0])

    @property
    def shape(self) -> StoreShape:
        waveforms = self.group["waveforms"]
        w = waveforms.shape
        return StoreShape(w[0], w[1], w[3], self.group["objects"].shape[1], self.group["arrivals"].shape[1],
                          int(waveforms.chunks[0]))

    def _per_sample_record(self, name: str, dtype: Any) -> tuple[NDArray[Any], tuple[int, ...]]:
        """A 1-D per-sample array read whole, or chunk by chunk when a chunk file is damaged:
        the samples of an unreadable chunk read as 0 (not complete / no checksum) and are
        returned as the second element."""
        arr = self.group[name]
        try:
            return np.asarray(arr[:], dtype=dtype), ()
        except Exception:  # noqa: BLE001 - find the damaged chunks below
            pass
        out = np.zeros(arr.shape[0], dtype=dtype)
        bad: list[int] = []
        for start in self.shape.chunk_starts():
            stop = self.shape.chunk_of(start)[1]
            try:
                out[start:stop] = np.asarray(arr[start:stop], dtype=dtype)
            except Exception:  # noqa: BLE001 - a damaged chunk of the record
                bad.extend(range(start, stop))
        return out, tuple(bad)

    def complete_mask(self) -> NDArray[np.bool_]:
        """(n_samples,) bool: samples recorded as complete (a damaged chunk of the record
        counts as not complete: those samples are made again on resume)."""
        return self._per_sample_record("complete", np.uint8)[0].astype(bool)

    def unreadable_records(self) -> tuple[int, ...]:
        """Samples whose ``complete`` or ``checksum`` chunk cannot be read."""
        return tuple(sorted(set(self._per_sample_record("complete", np.uint8)[1])
                            | set(self._per_sample_record("checksum", np.uint64)[1])))

    def checksums(self) -> NDArray[np.uint64]:
        """(n_samples,) recorded checksums (0 where not complete or unreadable)."""
        return self._per_sample_record("checksum", np.uint64)[0]

    def mark_incomplete(self, indices: list[int] | tuple[int, ...]) -> None:
        """Clear the completion flags of these samples (each chunk file of ``complete``
        rewritten atomically), so that the next run makes them again."""
        if not len(indices):
            return
        flags = self.group["complete"]
        for start in sorted({self.shape.chunk_of(int(i))[0] for i in indices}):
            stop = self.shape.chunk_of(start)[1]
            try:
                current = np.asarray(flags[start:stop], dtype=np.uint8)
            except Exception:  # noqa: BLE001 - a damaged record chunk: rewrite it as all incomplete
                current = np.zeros(stop - start, dtype=np.uint8)
            mine = [int(i) - start for i in indices if start <= int(i) < stop]
            current[mine] = 0
            flags[start:stop] = current

    @property
    def store_id(self) -> str:
        """The store's identity for the workers' visibility check (:func:`card_store_id`)."""
        return card_store_id(self.card)

    def writer(self) -> ChunkWriter:
        """Handles for the workers (arrays opened at the store's absolute path)."""
        return ChunkWriter(tuple(self.group[name] for name in (*SAMPLE_ARRAYS, "checksum", "complete")), self.shape,
                           str(self.root))

    def chunks_to_do(self) -> list[tuple[int, int]]:
        """``(start, stop)`` of every chunk with a sample not recorded complete (resume)."""
        complete = self.complete_mask()
        shape = self.shape
        return [shape.chunk_of(start) for start in shape.chunk_starts()
                if not complete[start:start + shape.chunk_samples].all()]

    def read_sample(self, index: int) -> dict[str, Any]:
        """One sample's arrays as stored (numpy), keyed by :data:`SAMPLE_ARRAYS`.

        Raises
        ------
        DatasetCorruptError
            When a chunk holding the sample cannot be decoded.
        """
        out: dict[str, Any] = {}
        for name in SAMPLE_ARRAYS:
            try:
                value = self.group[name][index]
            except Exception as exc:  # noqa: BLE001 - any decode failure is a damaged chunk
                raise self.corrupt_error([index], name, exc) from None
            out[name] = str(value) if name == "scene_json" else np.asarray(value)
        return out

    def corrupt_error(self, indices: Any, array: str, exc: BaseException) -> DatasetCorruptError:
        """The error for samples whose chunk of ``array`` cannot be read."""
        indices = [int(i) for i in np.atleast_1d(indices)]
        shown = ", ".join(str(i) for i in indices[:8]) + (" ..." if len(indices) > 8 else "")
        detail = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
        error = DatasetCorruptError(
            f"{self.path}: sample(s) {shown}: the {array!r} chunk cannot be read ({detail}); "
            f"`acoustisim dataset verify {self.path}` lists the damaged samples and "
            f"`acoustisim dataset generate SPEC.toml --out {self.path} --repair` makes them again")
        error.problem = f"the {array!r} chunk cannot be read ({detail})"
        return error
