"""Reading recording files (HDF5, format 1.x): lazily, ping range by ping range, and safely.

``open_recording(path)`` reads the header (attributes, channel positions, template, environment,
array description) and checks every dataset's storage and declared size
(``hdf5_safety``) before any sample is read; the pings are then read on demand
(``RecordingFile.read``, ``chunks``), so a recording of any length is processed in bounded
memory. ``read_recording(path)`` reads it all at once (the pings of a short file, or a
notebook's). ``/truth`` is never read.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from binsonar.errors import short_repr
from binsonar.files import as_path
from binsonar.recording.array_group import read_array_group
from binsonar.recording.hdf5_safety import (
    ReadLimits,
    attribute,
    checked_dataset,
    hard_object,
    number_attribute,
    open_hdf5,
    small_array,
    text_attribute,
)
from binsonar.recording.model import FORMAT_VERSION, Recording, RecordingError, RecordingHeader, Template
from binsonar.recording.source import PingSource

if TYPE_CHECKING:
    import h5py

CODES_ADC_BITS = 16
"""``adc_bits`` of int16 codes whose file does not say: the width of the stored codes."""


class RecordingFile(PingSource):
    """An open recording file (see the module notes); a context manager.

    Parameters
    ----------
    path : str or os.PathLike
    limits : ReadLimits
        What the file may declare.

    Raises
    ------
    RecordingError
        Missing, unreadable or malformed file, a dataset stored outside the file or declaring
        more than the limits, or a header value out of range (one line naming file, field, value).
    """

    def __init__(self, path: str | os.PathLike[str], limits: ReadLimits = ReadLimits()) -> None:
        self.path = as_path(path, "recording")
        self.limits = limits
        self._h5 = open_hdf5(self.path, "recording")
        try:
            self._read_header()
        except RecordingError:
            self.close()
            raise
        except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
            self.close()
            raise RecordingError(f"{self.path}: cannot read recording: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                                 ) from None

    def close(self) -> None:
        """Close the file."""
        try:
            self._h5.close()
        except (OSError, ValueError, RuntimeError):
            pass

    def _read_header(self) -> None:
        h5, limits = self._h5, self.limits
        where = str(self.path)
        version = text_attribute(h5, "format_version", where, limits)
        if version.split(".")[0] != FORMAT_VERSION.split(".")[0]:  # type: ignore[union-attr]
            raise RecordingError(f"{where}: format_version {version!r} is not supported (expected 1.x)")
        sample_rate = number_attribute(h5, "sample_rate_hz", where, limits)
        t0 = number_attribute(h5, "t0_s", where, limits)
        names = _channel_names(attribute(h5, "channel_names", where, limits), where)
        created_by = text_attribute(h5, "created_by", where, limits, required=False, default="")
        dset: h5py.Dataset = checked_dataset(  # type: ignore[assignment]
            h5, "waveforms", where, limits, kinds="iuf", required=True)
        n_pings, n_samples = self._waveform_shape(dset, where)
        volts_per_code = adc_bits = None
        stores_codes = dset.dtype.kind in "iu"
        if stores_codes:
            if dset.dtype != np.int16:
                raise RecordingError(f"{where}: /waveforms holds {dset.dtype} integers; ADC codes must be int16 "
                                     "(or store float volts)")
            volts_per_code = number_attribute(dset, "volts_per_code", f"{where}: /waveforms", limits)
            adc_bits = attribute(dset, "adc_bits", f"{where}: /waveforms", limits, required=False,
                                 default=CODES_ADC_BITS)
        elif dset.dtype.itemsize not in (4, 8):
            raise RecordingError(f"{where}: /waveforms holds {dset.dtype}; volts must be float32 or float64")
        positions = small_array(h5, "channel_positions_m", where, limits, kinds="iuf", required=True)
        self._clipped = checked_dataset(h5, "clipped", where, limits, kinds="biu")
        if self._clipped is not None and self._clipped.shape != (n_pings, 3):
            raise RecordingError(f"{where}: /clipped must have shape ({n_pings}, 3), got {self._clipped.shape}")
        self._pose = checked_dataset(h5, "pose", where, limits, kinds="iuf")
        if self._pose is not None and self._pose.shape != (n_pings, 6):
            raise RecordingError(f"{where}: /pose must have shape ({n_pings}, 6), got {self._pose.shape}")
        sound_speed, temperature = self._environment(where)
        self._waveforms = dset
        self._two_dimensional = dset.ndim == 2
        self.n_pings = n_pings
        self.header = RecordingHeader(
            sample_rate_hz=sample_rate,  # type: ignore[arg-type]
            n_samples=n_samples, t0_s=t0, channel_positions_m=positions,  # type: ignore[arg-type]
            channel_names=names, template=self._template(where), sound_speed_m_s=sound_speed,
            temperature_c=temperature, volts_per_code=volts_per_code, adc_bits=adc_bits,
            created_by=created_by or "", source=where, array=read_array_group(h5, where, limits),
            stores_codes=stores_codes)

    def _waveform_shape(self, dset: "h5py.Dataset", where: str) -> tuple[int, int]:
        shape = dset.shape
        if len(shape) == 2:
            shape = (1, *shape)
        if len(shape) != 3 or shape[1] != 3 or shape[0] < 1 or shape[2] < 1:
            raise RecordingError(f"{where}: /waveforms must have shape (n_pings, 3, n_samples), got {dset.shape}")
        if shape[2] > self.limits.max_samples_per_channel:
            raise RecordingError(f"{where}: /waveforms has {shape[2]} samples per channel, more than the "
                                 f"{self.limits.max_samples_per_channel} allowed (ReadLimits.max_samples_per_channel)")
        return int(shape[0]), int(shape[2])

    def _template(self, where: str) -> Template | None:
        samples = small_array(self._h5, "template", where, self.limits, kinds="iuf")
        if samples is None:
            return None
        tds = self._h5["template"]
        label = f"{where}: /template"
        rate = number_attribute(tds, "sample_rate_hz", label, self.limits)
        t0 = number_attribute(tds, "t0_s", label, self.limits, required=False)
        kind = text_attribute(tds, "kind", label, self.limits, required=False, default="transmitted-pulse",
                              max_length=64)
        try:
            return Template(samples, rate, 0.0 if t0 is None else t0, kind)  # type: ignore[arg-type]
        except RecordingError as exc:
            raise RecordingError(f"{where}: /{exc}") from None

    def _environment(self, where: str) -> tuple[float | None, float | None]:
        import h5py

        env = hard_object(self._h5, "environment", where)
        if env is None:
            return None, None
        if not isinstance(env, h5py.Group):
            raise RecordingError(f"{where}: /environment must be a group")
        label = f"{where}: /environment"
        return (number_attribute(env, "sound_speed_m_s", label, self.limits, required=False),
                number_attribute(env, "temperature_c", label, self.limits, required=False))

    def read_stored(self, start: int, stop: int) -> tuple[NDArray[Any], NDArray[np.bool_] | None,
                                                          NDArray[np.float64] | None]:
        """Pings ``start`` to ``stop`` as stored (see ``PingSource.read_stored``)."""
        try:
            data = self._waveforms[()][np.newaxis] if self._two_dimensional else self._waveforms[start:stop]
            clipped = None if self._clipped is None else np.asarray(self._clipped[start:stop]) != 0
            pose = None if self._pose is None else np.asarray(self._pose[start:stop], dtype=float)
        except (OSError, ValueError, TypeError, RuntimeError) as exc:
            raise RecordingError(f"{self.path}: cannot read pings {start}-{stop - 1}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        return data, clipped, pose


def _channel_names(raw: Any, where: str) -> tuple[str, ...]:
    values = np.atleast_1d(np.asarray(raw, dtype=object))
    if values.ndim != 1 or values.size != 3:
        raise RecordingError(f"{where}: channel_names must name 3 channels, got {short_repr(raw)}")
    names = []
    for value in values:
        if isinstance(value, bytes):
            try:
                value = value.decode("utf-8")
            except UnicodeDecodeError:
                raise RecordingError(f"{where}: channel_names must be UTF-8 text") from None
        if not isinstance(value, str):
            raise RecordingError(f"{where}: channel_names must be text, got {short_repr(raw)}")
        names.append(value)
    return tuple(names)


def open_recording(path: str | os.PathLike[str], *, limits: ReadLimits = ReadLimits()) -> RecordingFile:
    """Open a recording file for reading ping by ping (``RecordingFile``; use it in ``with``).

    Raises
    ------
    InputTypeError
        ``path`` is not a str or os.PathLike.
    RecordingError
        As ``RecordingFile``.
    """
    as_path(path, "open_recording: path")
    return RecordingFile(path, limits)


def read_recording(path: str | os.PathLike[str], *, keep_codes: bool = False,
                   limits: ReadLimits = ReadLimits()) -> Recording:
    """Read a whole recording file (format 1.x); never reads ``/truth``.

    For a long recording prefer ``open_recording`` and its ``chunks``: this holds every ping.

    Parameters
    ----------
    path : str or os.PathLike
    keep_codes : bool
        For a file of int16 ADC codes, keep the codes (``Recording.codes``) and make the volts only
        if ``waveforms`` is read: the detectors that work on codes then never make them.
        Ignored for files of volts.
    limits : ReadLimits
        What the file may declare.

    Raises
    ------
    InputTypeError
        ``path`` is not a str or os.PathLike.
    RecordingError
        Missing, unreadable, truncated or malformed file, naming the file, field and value.
    """
    as_path(path, "read_recording: path")
    with RecordingFile(path, limits) as recording_file:
        return recording_file.read(keep_codes=keep_codes)
