"""The ``/array`` group of a recording file: the array description (``binsonar.array_description``).

Layout (version 1.0)::

    /array                      group, attrs: version ("1.0"), sample_rate_hz
    /array/<name>               one group per channel, in channel order (left, centre, right),
                                attrs: index (0, 1, 2), role ("transmit", "receive", "both"),
                                position_m (3,), axis (3,), directivity ("piston", "table" or
                                "none"), diameter_m (piston only), and those of the electrical
                                chain that are known: gain_db, receive_sensitivity_db,
                                volts_per_code, adc_bits
    /array/<name>/beam_frequencies_hz, beam_angles_deg, beam_gain
                                table only: (k,), (m,), (k, m) linear one-way pressure gain

The same fields as the TOML description (README, "Array description").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from binsonar.array_description import (
    DESCRIPTION_VERSION,
    TOML_KEYS,
    ArrayDescription,
    ArrayDescriptionError,
    BeamTable,
    ChannelDescription,
    ElectricalChain,
    PistonDirectivity,
)
from binsonar.recording.hdf5_safety import (
    ReadLimits,
    attribute,
    hard_object,
    number_attribute,
    small_array,
    text_attribute,
)
from binsonar.recording.model import RecordingError

if TYPE_CHECKING:
    import h5py

GROUP = "array"


def write_array_group(h5: "h5py.File", array: ArrayDescription) -> None:
    """Write ``array`` as the ``/array`` group of an open file."""
    group = h5.create_group(GROUP, track_order=True)
    group.attrs["version"] = DESCRIPTION_VERSION
    group.attrs["sample_rate_hz"] = float(array.sample_rate_hz)
    for index, channel in enumerate(array.channels):
        sub = group.create_group(channel.name, track_order=True)
        sub.attrs["index"] = index
        sub.attrs["role"] = channel.role
        sub.attrs["position_m"] = np.asarray(channel.position_m, dtype=float)
        sub.attrs["axis"] = np.asarray(channel.axis, dtype=float)
        directivity = channel.directivity
        if isinstance(directivity, PistonDirectivity):
            sub.attrs["directivity"] = "piston"
            sub.attrs["diameter_m"] = float(directivity.diameter_m)
        elif isinstance(directivity, BeamTable):
            sub.attrs["directivity"] = "table"
            sub.create_dataset("beam_frequencies_hz", data=directivity.frequencies_hz)
            sub.create_dataset("beam_angles_deg", data=directivity.angles_deg)
            sub.create_dataset("beam_gain", data=directivity.gain)
        else:
            sub.attrs["directivity"] = "none"
        for key in TOML_KEYS["electrical"]:
            value = getattr(channel.electrical, key)
            if value is not None:
                sub.attrs[key] = value


def read_array_group(h5: "h5py.File", where: str, limits: ReadLimits) -> ArrayDescription | None:
    """The ``/array`` group as an ``ArrayDescription``; None when the file has none (format 1.0).

    Raises
    ------
    RecordingError
        A group that is there but incomplete or invalid, naming the field.
    """
    import h5py

    group = hard_object(h5, GROUP, where)
    if group is None:
        return None
    if not isinstance(group, h5py.Group):
        raise RecordingError(f"{where}: /array must be a group")
    label = f"{where}: /array"
    version = text_attribute(group, "version", label, limits)
    if version.split(".")[0] != DESCRIPTION_VERSION.split(".")[0]:  # type: ignore[union-attr]
        raise RecordingError(f"{label}: version {version!r} is not supported (expected 1.x)")
    rate = number_attribute(group, "sample_rate_hz", label, limits)
    try:
        names = list(group.keys())
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise RecordingError(f"{label}: cannot list the channels: {exc}") from None
    if len(names) != 3:
        raise RecordingError(f"{label}: must hold 3 channel groups, got {len(names)}")
    channels: list[tuple[int, ChannelDescription]] = []
    for name in names:
        channels.append(_read_channel(group, name, f"{label}/{name}", limits))
    order = sorted(index for index, _ in channels)
    if order != [0, 1, 2]:
        raise RecordingError(f"{label}: channel indices must be 0, 1, 2, got {order}")
    try:
        ordered = tuple(channel for _, channel in sorted(channels, key=lambda item: item[0]))
        return ArrayDescription(ordered, rate)  # type: ignore[arg-type]
    except ArrayDescriptionError as exc:
        raise RecordingError(f"{label}: {exc}") from None


def _read_channel(group: "h5py.Group", name: str, label: str, limits: ReadLimits) -> tuple[int, ChannelDescription]:
    import h5py

    sub = hard_object(group, name, label)
    if not isinstance(sub, h5py.Group):
        raise RecordingError(f"{label} must be a group")
    index = attribute(sub, "index", label, limits)
    if isinstance(index, bool) or not isinstance(index, int):
        raise RecordingError(f"{label}: index must be 0, 1 or 2, got {index!r}")
    kind = text_attribute(sub, "directivity", label, limits)
    directivity: PistonDirectivity | BeamTable | None
    try:
        if kind == "piston":
            directivity = PistonDirectivity(number_attribute(sub, "diameter_m", label, limits))  # type: ignore[arg-type]
        elif kind == "table":
            arrays = [small_array(sub, key, label, limits, kinds="iuf", required=True)
                      for key in ("beam_frequencies_hz", "beam_angles_deg", "beam_gain")]
            directivity = BeamTable(*arrays)
        elif kind == "none":
            directivity = None
        else:
            raise RecordingError(f"{label}: directivity must be 'piston', 'table' or 'none', got {kind!r}")
        electrical: dict[str, Any] = {}
        for key in TOML_KEYS["electrical"]:
            value = attribute(sub, key, label, limits, required=False)
            if isinstance(value, np.ndarray) and value.size == 1:
                value = value.reshape(()).item()
            if value is not None:
                electrical[key] = value
        channel = ChannelDescription(
            name=name,
            role=text_attribute(sub, "role", label, limits),  # type: ignore[arg-type]
            position_m=attribute(sub, "position_m", label, limits),
            axis=attribute(sub, "axis", label, limits),
            directivity=directivity,
            electrical=ElectricalChain(**electrical),
        )
    except ArrayDescriptionError as exc:
        raise RecordingError(f"{label}: {exc}") from None
    return index, channel
