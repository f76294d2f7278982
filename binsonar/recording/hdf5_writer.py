"""Writing recording files (HDF5, format 1.1): atomically, ping range by ping range.

Layout (``format_version`` "1.1"; documented in the README; a public contract)::

    /                       attrs: format_version ("1.1"), sample_rate_hz, t0_s (time of the
                            first sample after the transmit trigger, s), channel_names
                            (["left", "centre", "right"]), created_by
    /waveforms              (n_pings, 3, n_samples): int16 ADC codes with attrs
                            volts_per_code and adc_bits, or float32/float64 volts (attr units="V")
    /channel_positions_m    (3, 3) float64, channel positions in the head frame (m)
    /clipped                (n_pings, 3) uint8, 1 where the ADC clipped
    /template               optional (n,) float64 pulse or calibration echo, attrs
                            sample_rate_hz, t0_s (time of template sample 0 relative to the
                            pulse's reference instant, s), kind
    /environment            optional group, attrs sound_speed_m_s, temperature_c
    /pose                   optional (n_pings, 6) float64: x_m, y_m, z_m, yaw_deg, pitch_deg,
                            roll_deg of the head in the tank frame
    /array                  the array description (``array_group``; new in 1.1)
    /truth/...              optional, simulated pings only; never read by binsonar

Times of flight are measured from the transmit trigger: sample ``i`` of a channel is at
``t0_s + i / sample_rate_hz``, and the template's reference instant is what a time of flight
refers to. The same recording gives the same bytes (fixed creation metadata, ordered objects).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import numpy as np
from numpy.typing import NDArray

from binsonar.errors import InputTypeError
from binsonar.files import as_path, atomic_output
from binsonar.recording.array_group import write_array_group
from binsonar.recording.model import FORMAT_VERSION, POSE_COLUMNS, Recording, RecordingError, RecordingHeader, as_codes

if TYPE_CHECKING:
    import h5py


def _write_header(h5: "h5py.File", header: RecordingHeader, n_pings: int, as_codes_dtype: bool,
                  volts_dtype: np.dtype, with_pose: bool, truth: Mapping[str, Any] | None) -> dict[str, Any]:
    """Create every object of the file; returns the datasets the pings are written into."""
    import h5py

    h5.attrs["format_version"] = FORMAT_VERSION
    h5.attrs["sample_rate_hz"] = float(header.sample_rate_hz)
    h5.attrs["t0_s"] = float(header.t0_s)
    h5.attrs["channel_names"] = np.array(header.channel_names, dtype=h5py.string_dtype())
    h5.attrs["created_by"] = header.created_by
    shape = (n_pings, 3, header.n_samples)
    if as_codes_dtype:
        waveforms = h5.create_dataset("waveforms", shape=shape, dtype=np.int16)
        waveforms.attrs["volts_per_code"] = float(header.volts_per_code)  # type: ignore[arg-type]
        waveforms.attrs["adc_bits"] = int(header.adc_bits if header.adc_bits is not None else 16)
    else:
        waveforms = h5.create_dataset("waveforms", shape=shape, dtype=volts_dtype)
        waveforms.attrs["units"] = "V"
    h5.create_dataset("channel_positions_m", data=header.channel_positions_m)
    clipped = h5.create_dataset("clipped", shape=(n_pings, 3), dtype=np.uint8)
    template = header.template
    if template is not None:
        tds = h5.create_dataset("template", data=template.samples)
        tds.attrs["sample_rate_hz"] = float(template.sample_rate_hz)
        tds.attrs["t0_s"] = float(template.t0_s)
        tds.attrs["kind"] = template.kind
    if header.sound_speed_m_s is not None or header.temperature_c is not None:
        env = h5.create_group("environment")
        if header.sound_speed_m_s is not None:
            env.attrs["sound_speed_m_s"] = float(header.sound_speed_m_s)
        if header.temperature_c is not None:
            env.attrs["temperature_c"] = float(header.temperature_c)
    pose = None
    if with_pose:
        pose = h5.create_dataset("pose", shape=(n_pings, 6), dtype=np.float64)
        pose.attrs["columns"] = np.array(POSE_COLUMNS, dtype=h5py.string_dtype())
    write_array_group(h5, header.array)  # type: ignore[arg-type]
    if truth:
        group = h5.create_group("truth")
        for name, value in truth.items():
            if isinstance(value, str):
                group.attrs[name] = value
            else:
                group.create_dataset(name, data=value)
    return {"waveforms": waveforms, "clipped": clipped, "pose": pose}


def write_recording_chunks(
    path: str | os.PathLike[str],
    chunks: Iterable[Recording],
    n_pings: int,
    *,
    store_codes: bool,
    truth: Mapping[str, NDArray[Any] | str] | None = None,
    option: str = "-o",
) -> Path:
    """Write a recording from consecutive ranges of its pings, atomically, holding one range at
    a time.

    Parameters
    ----------
    path : str or os.PathLike
        Destination (``binsonar.files.atomic_output``: checked first; an existing regular file is
        replaced only once the new one is complete; links and special files are refused).
    chunks : iterable of Recording
        The pings in order, ``n_pings`` in all, sharing the first one's header.
    n_pings : int
    store_codes : bool
        Store int16 ADC codes (each chunk must carry ``codes``) instead of float volts.
    truth : mapping of name -> array or str, optional
        Ground truth datasets written under ``/truth`` (simulated pings only).
    option : str
        Names the destination in messages ("-o").

    Returns
    -------
    Path

    Raises
    ------
    RecordingError
        Chunks that disagree with the first one or with ``n_pings``.
    InputError
        The destination cannot be written (naming ``option`` and the user's path).
    """
    import h5py

    destination = as_path(path, option or "path")
    where = str(destination)
    with atomic_output(destination, option) as temporary:
        # Fixed creation metadata so the same inputs give byte-identical files.
        with h5py.File(temporary, "w", track_order=True, libver="earliest") as h5:
            datasets: dict[str, Any] | None = None
            header: RecordingHeader | None = None
            written = 0
            for chunk in chunks:
                if datasets is None:
                    header = chunk.header
                    volts_dtype = np.dtype(np.float64)
                    datasets = _write_header(h5, header, n_pings, store_codes, volts_dtype, chunk.pose is not None,
                                             truth)
                elif (chunk.n_samples != header.n_samples  # type: ignore[union-attr]
                      or (chunk.pose is None) != (datasets["pose"] is None)):
                    raise RecordingError(f"{where}: pings {written}-{written + chunk.n_pings - 1} differ in length or "
                                         "pose from the first ones")
                stop = written + chunk.n_pings
                if stop > n_pings:
                    raise RecordingError(f"{where}: more than the {n_pings} pings announced")
                if store_codes:
                    if chunk.codes is None:
                        raise RecordingError(f"{where}: codes are to be stored but pings {written}-{stop - 1} have none")
                    datasets["waveforms"][written:stop] = chunk.codes
                else:
                    datasets["waveforms"][written:stop] = chunk.waveforms
                datasets["clipped"][written:stop] = np.asarray(chunk.clipped, dtype=np.uint8)
                if datasets["pose"] is not None:
                    datasets["pose"][written:stop] = chunk.pose
                written = stop
            if written != n_pings:
                raise RecordingError(f"{where}: {written} pings written, {n_pings} announced")
    return destination


def write_recording(
    path: str | os.PathLike[str],
    recording: Recording,
    *,
    codes: NDArray[np.integer] | None = None,
    truth: Mapping[str, NDArray[Any] | str] | None = None,
) -> Path:
    """Write a recording atomically (a temporary file in the same folder, then a rename).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; an existing regular file is replaced only once the new one is complete.
        Its folder must exist; a symbolic link, folder or device there is refused. The file gets
        mode 0666 filtered by the umask.
    recording : Recording
    codes : int ndarray (n_pings, 3, n_samples), optional
        Store these int16 ADC codes (with ``recording.volts_per_code``) instead of float volts.
        A recording that carries its codes (``Recording.codes``) is stored as codes anyway.
    truth : mapping of name -> array or str, optional
        Ground truth datasets written under ``/truth`` (simulated pings only).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputTypeError
        ``path`` or ``recording`` of the wrong type.
    RecordingError
        Codes that do not fit the recording.
    InputError
        The destination cannot be written.
    """
    destination = as_path(path, "write_recording: path")
    if not isinstance(recording, Recording):
        raise InputTypeError(f"write_recording: recording must be a Recording, got {type(recording).__name__}")
    where = str(destination)
    if codes is not None:
        if recording.volts_per_code is None:
            raise RecordingError(f"{where}: volts_per_code is required with int16 codes")
        stored = as_codes(codes, recording.volts_per_code, where)
        if stored.shape != (recording.n_pings, 3, recording.n_samples):
            raise RecordingError(f"{where}: codes shape {np.shape(codes)} != waveforms "
                                 f"{(recording.n_pings, 3, recording.n_samples)}")
        recording = Recording(None, codes=stored, clipped=recording.clipped, pose=recording.pose,
                              **recording.header_fields())
    return write_recording_chunks(destination, (recording,), recording.n_pings,
                                  store_codes=recording.codes is not None, truth=truth, option="")
