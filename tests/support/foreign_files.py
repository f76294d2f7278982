"""Writing pings in the formats ``binsonar import`` reads, the way DAQs and lab scripts do (with
soundfile, numpy, scipy.io and h5py directly, never through binsonar), and the array description
(TOML) that goes with them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def frames_of(pings: np.ndarray) -> np.ndarray:
    """(n_pings, 3, n) -> the (n_pings n, 3) frames of a continuous multi-channel stream."""
    return np.ascontiguousarray(np.asarray(pings).transpose(0, 2, 1).reshape(-1, 3))


def write_wav(path: Path, pings: np.ndarray, sample_rate_hz: float, subtype: str = "PCM_16") -> Path:
    """A 3-channel WAV of the pings one after another. Integer subtypes take int codes, shifted
    left to the file's width as a DAQ stores them (24-bit codes in int32 frames: code << 8)."""
    import soundfile

    frames = frames_of(pings)
    if subtype == "PCM_24":
        frames = frames.astype(np.int32) << 8
    elif subtype == "PCM_32":
        frames = frames.astype(np.int32)
    soundfile.write(str(path), frames, int(round(sample_rate_hz)), subtype=subtype)
    return path


MAT73_HEADER_TEXT = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."


def write_mat73(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """A MATLAB v7.3 file: HDF5 behind a 512-byte user block holding MATLAB's 128-byte header,
    each variable stored column-major (h5py sees MATLAB's axes reversed)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as h5:
        for name, value in variables.items():
            array = np.asarray(value)
            dset = h5.create_dataset(name, data=np.ascontiguousarray(array.transpose()))
            dset.attrs["MATLAB_class"] = np.bytes_({"int16": "int16", "int32": "int32", "float64": "double",
                                                    "float32": "single"}[array.dtype.name])
    header = MAT73_HEADER_TEXT.ljust(116, b" ") + b"\0" * 8 + bytes([0x00, 0x02]) + b"IM"
    with open(path, "r+b") as handle:
        handle.write(header.ljust(512, b"\0"))
    return path


def array_toml(array: Any, import_table: dict[str, Any]) -> str:
    """An array description (a ``binsonar.array_description.ArrayDescription``) with an ``[import]``
    table, as TOML text."""
    import tomli_w

    mapping = array.to_mapping()
    mapping["import"] = dict(import_table)
    return tomli_w.dumps(mapping)
