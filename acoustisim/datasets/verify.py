"""Check a dataset store: every sample complete, every stored sample matching its checksum."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from acoustisim.datasets.store import SAMPLE_ARRAYS, DatasetCorruptError, DatasetStore, sample_checksum

VERIFY_BLOCK = 64
"""Samples read per call, rounded down to whole chunks (at least one); a failing block is
re-read sample by sample to name the culprit."""


@dataclass(frozen=True)
class VerifyReport:
    """Outcome of :func:`verify`.

    Attributes
    ----------
    path : str
    n_samples, n_complete : int
    missing : tuple of int
        Samples not recorded complete.
    corrupt : tuple of (int, str)
        Complete samples whose chunks cannot be read or do not match the recorded checksum.
    stray_files : tuple of str
        Temporary ``*.partial`` files left by writes interrupted by a kill (harmless).
    damaged_records : tuple of int
        Samples whose chunk of the ``complete`` or ``checksum`` record cannot be read (they
        count as missing, or as corrupt when only the checksum is lost, and are made again
        on resume).
    """

    path: str
    n_samples: int
    n_complete: int
    missing: tuple[int, ...]
    corrupt: tuple[tuple[int, str], ...]
    stray_files: tuple[str, ...]
    damaged_records: tuple[int, ...] = ()

    @property
    def ok(self) -> bool:
        """Complete and uncorrupted."""
        return not self.missing and not self.corrupt

    def as_dict(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["ok"] = self.ok
        data["corrupt"] = [{"sample": i, "problem": why} for i, why in self.corrupt]
        data["missing"] = list(self.missing)
        return data


def _read_block(store: DatasetStore, start: int, stop: int) -> dict[str, Any]:
    return {name: store.array(name)[start:stop] for name in SAMPLE_ARRAYS}


def _check_one(store: DatasetStore, index: int, expected: int) -> str | None:
    try:
        values = store.read_sample(index)
    except DatasetCorruptError as exc:
        return f"unreadable: {exc.problem or exc}"
    got = sample_checksum(values)
    return None if got == expected else f"checksum {got:016x} != recorded {expected:016x}"


def verify(path: str | Path) -> VerifyReport:
    """Verify completeness and per-sample checksums of a dataset store.

    Reads every complete sample back (blocks of :data:`VERIFY_BLOCK` samples) and compares the
    checksum of its stored bytes (:func:`~acoustisim.datasets.store.sample_checksum`) with
    the one recorded when it was written.
    """
    store = DatasetStore(path, mode="r")
    complete = store.complete_mask()
    recorded = store.checksums()
    corrupt: list[tuple[int, str]] = []
    done = np.flatnonzero(complete)
    chunk = store.shape.chunk_samples
    block_size = chunk * max(1, VERIFY_BLOCK // chunk)  # whole chunks: each chunk file decoded once
    for start in range(0, store.n_samples, block_size):
        stop = min(start + block_size, store.n_samples)
        wanted = done[(done >= start) & (done < stop)]
        if wanted.size == 0:
            continue
        try:
            block = _read_block(store, start, stop)
        except Exception:  # noqa: BLE001 - pinpoint the bad sample below
            block = None
        for i in wanted:
            if block is None:
                problem = _check_one(store, int(i), int(recorded[i]))
            else:
                values = {name: (str(block[name][i - start]) if name == "scene_json" else block[name][i - start])
                          for name in SAMPLE_ARRAYS}
                got = sample_checksum(values)
                problem = None if got == int(recorded[i]) else f"checksum {got:016x} != recorded {int(recorded[i]):016x}"
            if problem is not None:
                corrupt.append((int(i), problem))
    stray = tuple(sorted(str(p.relative_to(store.path)) for p in store.path.rglob("*.partial")))
    return VerifyReport(
        path=str(store.path),
        n_samples=store.n_samples,
        n_complete=int(complete.sum()),
        missing=tuple(int(i) for i in np.flatnonzero(~complete)),
        corrupt=tuple(corrupt),
        stray_files=stray,
        damaged_records=store.unreadable_records(),
    )
