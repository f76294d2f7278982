"""The recording: what the hardware writes and the pipeline reads (HDF5, versioned).

- ``model``: ``Recording`` (pings in memory, as volts or ADC codes), ``RecordingHeader``,
  ``Template``, ``RecordingError`` and the checks of every field;
- ``hdf5_reader``: ``open_recording`` (a ``RecordingFile``, read ping range by ping range),
  ``read_recording`` (all at once);
- ``hdf5_writer``: ``write_recording``, ``write_recording_chunks`` (atomic, byte-deterministic);
  the file layout is documented there and in the README;
- ``hdf5_safety``: HDF5 that cannot read outside the file or beyond its declared sizes
  (``ReadLimits``);
- ``array_group``: the ``/array`` group (``binsonar.array_description``);
- ``source``: ``PingSource``, the interface of every reader (recordings and imported files).

Importing this package loads numpy only; h5py is imported when a file is read or written.
"""

from binsonar.recording.hdf5_reader import RecordingFile, open_recording, read_recording
from binsonar.recording.hdf5_safety import ReadLimits
from binsonar.recording.hdf5_writer import write_recording, write_recording_chunks
from binsonar.recording.model import (
    CHANNEL_NAMES,
    FORMAT_VERSION,
    POSE_COLUMNS,
    Recording,
    RecordingError,
    RecordingHeader,
    Template,
    as_codes,
    as_poses,
    as_volts,
)
from binsonar.recording.source import CHUNK_BYTES, PingSource

__all__ = (
    "CHANNEL_NAMES",
    "CHUNK_BYTES",
    "FORMAT_VERSION",
    "POSE_COLUMNS",
    "PingSource",
    "ReadLimits",
    "Recording",
    "RecordingError",
    "RecordingFile",
    "RecordingHeader",
    "Template",
    "as_codes",
    "as_poses",
    "as_volts",
    "open_recording",
    "read_recording",
    "write_recording",
    "write_recording_chunks",
)
