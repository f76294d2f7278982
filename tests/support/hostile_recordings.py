"""A corpus of hostile recordings, imported files and argument lists for ``binsonar``.

Each case is a file (made here with h5py, numpy, soundfile and scipy only: the same corpus
serves any version of binsonar, e.g. the baseline checkout) and the command lines to run on it,
with what the contract expects: exit 0 ("accept") or exit 2 with one line ("refuse"). Used by
the unit tests (``test_recording_hostile.py``), the fuzz tests and the corpus runner
``benchmarks/hostile_recordings.py``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

FS = 20e6
N_SAMPLES = 4096
VOLTS_PER_CODE = 2.0 / 4096


@dataclass(frozen=True)
class Case:
    """One hostile input.

    Attributes
    ----------
    name : str
        What is wrong (or "valid ...").
    kind : str
        The family it belongs to ("recording", "import", "arguments", "output").
    argv : tuple of str
        The ``binsonar`` command line; ``{file}``, ``{array}`` and ``{dir}`` are the case's file,
        the corpus's array description and the corpus folder.
    expect : {"accept", "refuse"}
    """

    name: str
    kind: str
    argv: tuple[str, ...]
    expect: str


def pulse(n: int = 201) -> np.ndarray:
    """The thesis pulse (5 us Gaussian at 500 kHz) sampled at 20 MHz, centred."""
    t = (np.arange(n) - n // 2) / FS
    return np.exp(-13.8 * t ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * t)


def clean_codes(n_pings: int = 2, n_samples: int = N_SAMPLES, seed: int = 0) -> np.ndarray:
    """int16 codes (n_pings, 3, n) of echoes at 60-62 us with noise, a 12-bit ADC's range."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / FS
    volts = np.zeros((n_pings, 3, n_samples))
    for channel, delay in enumerate((61e-6, 60e-6, 62e-6)):
        tau = t - delay
        volts[:, channel] += 0.3 * np.exp(-13.8 * tau ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * tau)
    volts += rng.normal(0.0, 0.003, volts.shape)
    return np.clip(np.round(volts / VOLTS_PER_CODE), -2047, 2047).astype(np.int16)


def write_raw_recording(path: Path, *, codes: np.ndarray | None = None, edit: Callable | None = None,
                        version: str = "1.0", libver: str = "earliest") -> Path:
    """A format-1.0 recording written with h5py alone (no binsonar), then ``edit(h5)``."""
    import h5py

    codes = clean_codes() if codes is None else codes
    with h5py.File(path, "w", libver=(libver, "latest")) as h5:
        h5.attrs["format_version"] = version
        h5.attrs["sample_rate_hz"] = FS
        h5.attrs["t0_s"] = 0.0
        h5.attrs["channel_names"] = np.array(["left", "centre", "right"], dtype=h5py.string_dtype())
        h5.attrs["created_by"] = "hostile corpus"
        dset = h5.create_dataset("waveforms", data=codes)
        dset.attrs["volts_per_code"] = VOLTS_PER_CODE
        dset.attrs["adc_bits"] = 12
        h5.create_dataset("channel_positions_m", data=np.array([[-0.065, 0, 0], [0, 0, 0], [0.065, 0, 0]], float))
        h5.create_dataset("clipped", data=np.zeros(codes.shape[:2], dtype=np.uint8))
        template = h5.create_dataset("template", data=pulse())
        template.attrs["sample_rate_hz"] = FS
        template.attrs["t0_s"] = -100 / FS
        template.attrs["kind"] = "transmitted-pulse"
        env = h5.create_group("environment")
        env.attrs["sound_speed_m_s"] = 1482.0
        env.attrs["temperature_c"] = 20.0
        if edit is not None:
            edit(h5)
    return path


def _replace_waveforms(h5, **kwargs) -> None:
    attrs = dict(h5["waveforms"].attrs)
    del h5["waveforms"]
    dset = h5.create_dataset("waveforms", **kwargs)
    for key, value in attrs.items():
        dset.attrs[key] = value


def _set_attr(target: str, key: str, value) -> Callable:
    def edit(h5) -> None:
        (h5 if target == "/" else h5[target]).attrs[key] = value
    return edit


def _delete(name: str) -> Callable:
    def edit(h5) -> None:
        del h5[name]
    return edit


def _external_storage(h5) -> None:
    attrs = dict(h5["waveforms"].attrs)
    del h5["waveforms"]
    size = os.path.getsize("/etc/passwd") // 2 * 2
    n = max(size // 6, 1)
    dset = h5.create_dataset("waveforms", shape=(1, 3, n), dtype=np.int16, external=[("/etc/passwd", 0, 6 * n)])
    for key, value in attrs.items():
        dset.attrs[key] = value
    del h5["clipped"]


def _external_link(folder: Path) -> Callable:
    def edit(h5) -> None:
        import h5py

        other = folder / "linked-target.h5"
        with h5py.File(other, "w") as target:
            target.create_dataset("data", data=clean_codes())
        attrs = dict(h5["waveforms"].attrs)
        del h5["waveforms"]
        h5["waveforms"] = h5py.ExternalLink(str(other), "/data")
        del attrs
    return edit


def _virtual(folder: Path) -> Callable:
    def edit(h5) -> None:
        import h5py

        other = folder / "virtual-source.h5"
        with h5py.File(other, "w") as source:
            source.create_dataset("data", data=clean_codes())
        attrs = dict(h5["waveforms"].attrs)
        del h5["waveforms"]
        layout = h5py.VirtualLayout(shape=(2, 3, N_SAMPLES), dtype=np.int16)
        layout[:] = h5py.VirtualSource(str(other), "data", shape=(2, 3, N_SAMPLES))
        dset = h5.create_virtual_dataset("waveforms", layout)
        for key, value in attrs.items():
            dset.attrs[key] = value
    return edit


def _sparse_bomb(h5) -> None:
    # Declares 10,000 pings of 3 x 1,000,000 codes (60 GB) and stores none of them: read back as
    # the fill value, a 60 GB allocation from a file of kilobytes.
    _replace_waveforms(h5, shape=(10000, 3, 1_000_000), dtype=np.int16, chunks=(1, 3, 1_000_000),
                       compression="gzip")
    del h5["clipped"]


def _gzip_bomb(h5) -> None:
    # 16 pings of 3 x 2^20 zeros, gzip level 9: 100 MB declared in about 100 kB.
    _replace_waveforms(h5, data=np.zeros((16, 3, 2**20), dtype=np.int16), chunks=(1, 3, 2**20),
                       compression="gzip", compression_opts=9)
    del h5["clipped"]
    h5.create_dataset("clipped", data=np.zeros((16, 3), dtype=np.uint8))


Built = tuple[Case, Callable[[Path], object], str]
"""A case, the function writing its file at a path, and the file's suffix."""


def recording_cases(folder: Path) -> list[Built]:
    """Hostile (and two valid) recording files, each run through detect and localize."""
    folder = Path(folder)
    float_ok = lambda h5: _replace_waveforms(h5, data=clean_codes() * VOLTS_PER_CODE)  # noqa: E731
    builders: list[tuple[str, str, Callable]] = [
        ("valid format 1.0 recording", "accept", lambda p: write_raw_recording(p)),
        ("valid recording of float volts", "accept", lambda p: write_raw_recording(p, edit=float_ok)),
        ("valid recording with a clipped ping", "accept",
         lambda p: write_raw_recording(p, codes=np.where(np.arange(N_SAMPLES) == 9, 2047, clean_codes()).astype(np.int16))),
        ("sample rate 1 Hz", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "sample_rate_hz", 1.0))),
        ("sample rate 1e300 Hz", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "sample_rate_hz", 1e300))),
        ("sample rate NaN", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "sample_rate_hz", np.nan))),
        ("sample rate -20 MHz", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "sample_rate_hz", -20e6))),
        ("sample rate a string", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "sample_rate_hz", "fast"))),
        ("t0 1e300 s", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "t0_s", 1e300))),
        ("adc_bits 0", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("waveforms", "adc_bits", 0))),
        ("adc_bits 1000", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("waveforms", "adc_bits", 1000))),
        ("volts_per_code 0", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("waveforms", "volts_per_code", 0.0))),
        ("volts_per_code 1e300", "refuse",
         lambda p: write_raw_recording(p, edit=_set_attr("waveforms", "volts_per_code", 1e300))),
        ("clipped as strings", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            _delete("clipped")(h5), h5.create_dataset("clipped", data=np.array([[b"yes"] * 3] * 2))))),
        ("int32 codes beyond int16", "refuse", lambda p: write_raw_recording(
            p, codes=(clean_codes().astype(np.int32) * 1000))),
        ("external storage on /etc/passwd", "refuse", lambda p: write_raw_recording(p, edit=_external_storage)),
        ("external link to another file", "refuse", lambda p: write_raw_recording(p, edit=_external_link(folder))),
        ("virtual dataset", "refuse", lambda p: write_raw_recording(p, edit=_virtual(folder))),
        ("60 GB declared, nothing stored", "refuse", lambda p: write_raw_recording(p, edit=_sparse_bomb)),
        ("gzip bomb 1000x", "refuse", lambda p: write_raw_recording(p, edit=_gzip_bomb)),
        ("NaN volts", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: _replace_waveforms(
            h5, data=np.where(np.arange(N_SAMPLES) == 7, np.nan, clean_codes() * VOLTS_PER_CODE)))),
        ("1e300 volts", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: _replace_waveforms(
            h5, data=np.where(np.arange(N_SAMPLES) == 7, 1e300, clean_codes() * VOLTS_PER_CODE)))),
        ("template at 1 Hz", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("template", "sample_rate_hz", 1.0))),
        ("template at 1e10 Hz", "refuse",
         lambda p: write_raw_recording(p, edit=_set_attr("template", "sample_rate_hz", 1e10))),
        ("template with NaN", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            h5["template"].__setitem__(5, np.nan)))),
        ("channel positions 1e300", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            _delete("channel_positions_m")(h5), h5.create_dataset("channel_positions_m", data=np.full((3, 3), 1e300))))),
        ("channel positions coincide", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            _delete("channel_positions_m")(h5), h5.create_dataset("channel_positions_m", data=np.zeros((3, 3)))))),
        ("channel positions (2, 3)", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            _delete("channel_positions_m")(h5), h5.create_dataset("channel_positions_m", data=np.zeros((2, 3)))))),
        ("waveforms missing", "refuse", lambda p: write_raw_recording(p, edit=_delete("waveforms"))),
        ("waveforms a group", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: (
            _delete("waveforms")(h5), h5.create_group("waveforms")))),
        ("waveforms 1-D", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: _replace_waveforms(
            h5, data=np.zeros(N_SAMPLES, dtype=np.int16)))),
        ("waveforms with 4 channels", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: _replace_waveforms(
            h5, data=np.zeros((2, 4, N_SAMPLES), dtype=np.int16)))),
        ("waveforms of strings", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: _replace_waveforms(
            h5, data=np.array([[[b"x"] * 8] * 3])))),
        ("format_version 2.0", "refuse", lambda p: write_raw_recording(p, version="2.0")),
        ("format_version missing", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: h5.attrs.__delitem__(
            "format_version"))),
        ("format_version a number", "refuse", lambda p: write_raw_recording(p, edit=_set_attr("/", "format_version", 1.0))),
        ("two channel names", "refuse", lambda p: write_raw_recording(p, edit=_set_attr(
            "/", "channel_names", np.array([b"l", b"r"])))),
        ("pose NaN", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: h5.create_dataset(
            "pose", data=np.full((2, 6), np.nan)))),
        ("pose of the wrong shape", "refuse", lambda p: write_raw_recording(p, edit=lambda h5: h5.create_dataset(
            "pose", data=np.zeros((3, 6))))),
        ("sound speed 1e300", "refuse", lambda p: write_raw_recording(
            p, edit=_set_attr("environment", "sound_speed_m_s", 1e300))),
        ("sound speed a string", "refuse", lambda p: write_raw_recording(
            p, edit=_set_attr("environment", "sound_speed_m_s", "fast"))),
        ("a 4 MB attribute", "refuse", lambda p: write_raw_recording(p, edit=_big_attribute, libver="latest")),
    ]
    return [(Case(name, "recording", ("{file}",), expect), builder, ".h5") for name, expect, builder in builders]


def _big_attribute(h5) -> None:
    import h5py

    del h5.attrs["created_by"]
    space = h5py.h5s.create_simple((2**19,))
    attr = h5py.h5a.create(h5.id, b"created_by", h5py.h5t.NATIVE_DOUBLE, space)
    attr.write(np.zeros(2**19))


def damaged_file_cases(folder: Path) -> list[Built]:
    """Files that are not recordings at all, or damaged ones."""
    def truncated(p: Path) -> None:
        write_raw_recording(p)
        data = p.read_bytes()
        p.write_bytes(data[: len(data) // 2])

    def flipped(p: Path) -> None:
        write_raw_recording(p)
        data = bytearray(p.read_bytes())
        rng = np.random.default_rng(1)
        for i in rng.integers(0, 2048, 40):  # the superblock and object headers
            data[int(i)] ^= 0xFF
        p.write_bytes(bytes(data))

    builders: list[tuple[str, Callable]] = [
        ("empty file", lambda p: p.write_bytes(b"")),
        ("random bytes", lambda p: p.write_bytes(np.random.default_rng(0).bytes(10000))),
        ("truncated HDF5", truncated),
        ("HDF5 with flipped header bytes", flipped),
        ("a folder", lambda p: p.mkdir()),
        ("a FIFO", lambda p: os.mkfifo(p)),
    ]
    cases = [(Case(name, "recording", ("{file}",), "refuse"), builder, ".h5") for name, builder in builders]
    cases.append((Case("/dev/zero", "recording", ("/dev/zero",), "refuse"), lambda p: None, ".h5"))
    cases.append((Case("missing file", "recording", ("{dir}/absent.h5",), "refuse"), lambda p: None, ".h5"))
    return cases


def array_toml_text(n_samples: int = N_SAMPLES, extra: str = "") -> str:
    """An array description for the corpus's imported files (12-bit codes, the seed head)."""
    channels = []
    for name, role, x in (("left", "receive", -0.065), ("centre", "both", 0.0), ("right", "receive", 0.065)):
        channels.append(
            f'[[channels]]\nname = "{name}"\nrole = "{role}"\nposition_m = [{x}, 0.0, 0.0]\n'
            f'[channels.directivity]\nkind = "piston"\ndiameter_m = 0.019\n'
            f"[channels.electrical]\nvolts_per_code = {VOLTS_PER_CODE!r}\nadc_bits = 12\n")
    return (f'version = "1.0"\nsample_rate_hz = {FS!r}\n\n' + "\n".join(channels)
            + f'\n[import]\ntemplate = "pulse.npy"\ntemplate_t0_s = {-100 / FS!r}\nsound_speed_m_s = 1482.0\n'
            + extra)


def import_cases(folder: Path) -> list[Built]:
    """Hostile (and valid) WAV, NumPy, MATLAB and CSV files, and array descriptions."""
    import soundfile

    folder = Path(folder)
    np.save(folder / "pulse.npy", pulse())
    (folder / "array.toml").write_text(array_toml_text())
    frames = clean_codes(1)[0].T  # (n, 3)

    def wav(subtype: str, data: np.ndarray, rate: int = int(FS)) -> Callable:
        return lambda p: soundfile.write(str(p), data, rate, subtype=subtype)

    def npy_header_lie(p: Path) -> None:
        # A header declaring 3 x 10^11 int16 (600 GB) followed by 64 bytes.
        with open(p, "wb") as handle:
            np.lib.format.write_array_header_1_0(handle, {"descr": "<i2", "fortran_order": False,
                                                          "shape": (3, 10**11)})
            handle.write(bytes(64))

    def mat_v5(p: Path, data: dict) -> None:
        import scipy.io

        scipy.io.savemat(str(p), data)

    def csv(p: Path, text: str) -> None:
        p.write_text(text)

    def deep_toml(p: Path) -> None:
        write_raw_wav = wav("PCM_16", frames)
        write_raw_wav(p)
        (folder / "deep.toml").write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")

    good_csv = "left,centre,right\n" + "\n".join(",".join(repr(float(v)) for v in row * VOLTS_PER_CODE)
                                               for row in frames) + "\n"
    builders: list[tuple[str, str, str, Callable]] = [
        ("valid 16-bit WAV", ".wav", "accept", wav("PCM_16", frames)),
        ("valid 24-bit WAV", ".wav", "accept", wav("PCM_24", frames.astype(np.int32) << 8)),
        ("valid float WAV", ".wav", "accept", wav("FLOAT", frames * VOLTS_PER_CODE)),
        ("valid .npy", ".npy", "accept", lambda p: np.save(p, clean_codes())),
        ("valid .npz", ".npz", "accept", lambda p: np.savez(p, waveforms=clean_codes())),
        ("valid .mat v5", ".mat", "accept", lambda p: mat_v5(p, {"waveforms": clean_codes()})),
        ("valid CSV", ".csv", "accept", lambda p: csv(p, good_csv)),
        ("WAV with 2 channels", ".wav", "refuse", wav("PCM_16", frames[:, :2])),
        ("WAV at 44.1 kHz", ".wav", "refuse", wav("PCM_16", frames, 44100)),
        ("WAV in mu-law", ".wav", "refuse", wav("ULAW", frames * VOLTS_PER_CODE)),
        ("WAV truncated", ".wav", "refuse", lambda p: (wav("PCM_16", frames)(p), p.write_bytes(p.read_bytes()[:60]))),
        ("random bytes as WAV", ".wav", "refuse", lambda p: p.write_bytes(np.random.default_rng(2).bytes(5000))),
        ("pickled object .npy", ".npy", "refuse", lambda p: np.save(p, np.array([{"a": 1}], dtype=object),
                                                                  allow_pickle=True)),
        ("1-D .npy", ".npy", "refuse", lambda p: np.save(p, np.zeros(100))),
        ("truncated .npy", ".npy", "refuse", lambda p: (np.save(p, clean_codes()), p.write_bytes(p.read_bytes()[:500]))),
        (".npy whose header lies", ".npy", "refuse", npy_header_lie),
        ("unsigned .npy", ".npy", "refuse", lambda p: np.save(p, clean_codes().astype(np.uint16))),
        (".npz with two arrays", ".npz", "refuse", lambda p: np.savez(p, a=clean_codes(), b=clean_codes())),
        ("random bytes as .npz", ".npz", "refuse", lambda p: p.write_bytes(np.random.default_rng(3).bytes(4000))),
        (".mat of text only", ".mat", "refuse", lambda p: mat_v5(p, {"note": "hello"})),
        ("random bytes as .mat", ".mat", "refuse", lambda p: p.write_bytes(np.random.default_rng(4).bytes(4000))),
        ("CSV with a text cell", ".csv", "refuse", lambda p: csv(p, "left,centre,right\n1,2,3\n4,x,6\n")),
        ("CSV with 2 columns", ".csv", "refuse", lambda p: csv(p, "1,2\n3,4\n5,6\n")),
        ("CSV with a bad header", ".csv", "refuse", lambda p: csv(p, "a,b,c\n1,2,3\n4,5,6\n")),
        ("empty CSV", ".csv", "refuse", lambda p: csv(p, "")),
    ]
    cases = [(Case(name, "import", ("{file}",), expect), builder, suffix) for name, suffix, expect, builder in builders]
    cases.append((Case("array description nested 5000 deep", "import", ("{file}", "--array", "{dir}/deep.toml"),
                       "refuse"), deep_toml, ".wav"))
    cases.append((Case("array description missing", "import", ("{file}", "--array", "{dir}/absent.toml"), "refuse"),
                  wav("PCM_16", frames), ".wav"))
    return cases


def argument_cases() -> list[Case]:
    """Hostile argument lists on a valid recording (``{file}``)."""
    raw = [
        (("detect", "{file}", "--method", "bogus"), "refuse"),
        (("detect", "{file}", "--option", "nonsense"), "refuse"),
        (("detect", "{file}", "--option", "guard_s=1e300", "--method", "ca-cfar"), "refuse"),
        (("detect", "{file}", "--pfa", "1e300"), "refuse"),
        (("detect", "{file}", "--pfa", "nan"), "refuse"),
        (("detect", "{file}", "--noise-window", "nan", "1"), "refuse"),
        (("detect", "{file}", "--bandpass", "1e300", "2e300"), "refuse"),
        (("detect", "{file}", "--template", "/dev/zero"), "refuse"),
        (("detect", "{file}", "--template", "{dir}"), "refuse"),
        (("detect", "{file}", "--full-scale-v", "-1"), "refuse"),
        (("detect", "{file}", "--transducer-diameter-m", "1e300"), "refuse"),
        (("detect", "{file}", "--array", "{dir}/array.toml"), "refuse"),
        (("localize", "{file}", "--sound-speed", "nan"), "refuse"),
        (("localize", "{file}", "--tof-floor-ns", "-5"), "refuse"),
        (("localize", "{file}", "--method", "bogus"), "refuse"),
        (("detect", "{file}", "--method", "seed-4", "--json"), "accept"),
        (("localize", "{file}", "--json"), "accept"),
    ]
    return [Case(" ".join(argv[2:]), "arguments", argv, expect) for argv, expect in raw]


def output_cases() -> list[Case]:
    """``binsonar import -o`` onto paths that must be refused (``{file}`` a valid WAV)."""
    raw = [
        ("-o onto a symbolic link", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "{dir}/link.h5")),
        ("-o onto /dev/null", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "/dev/null")),
        ("-o in a missing folder", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "{dir}/no/such/x.h5")),
        ("-o empty", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "")),
        ("-o a 300-character name", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "{dir}/" + "n" * 300)),
        ("-o onto the input", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "{file}")),
        ("-o onto a folder", ("import", "{file}", "--array", "{dir}/array.toml", "-o", "{dir}")),
    ]
    return [Case(name, "output", argv, "refuse") for name, argv in raw]


@dataclass(frozen=True)
class Run:
    """One command line of the corpus: the case and the ``binsonar`` arguments."""

    case: Case
    argv: tuple[str, ...]


def build_corpus(folder: Path) -> list[Run]:
    """Write every case's file into ``folder`` and return the command lines to run.

    Recording files run through ``detect`` and ``localize``; imported files through ``detect``,
    ``localize`` (with ``--array``) and ``import``; argument and output cases as written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    runs: list[Run] = []
    made = recording_cases(folder) + damaged_file_cases(folder)
    for index, (case, builder, suffix) in enumerate(made):
        path = folder / f"rec-{index:03d}{suffix}"
        builder(path)
        for verb in ("detect", "localize"):
            runs.append(Run(case, (verb, *_fill(case.argv, path, folder))))
    for index, (case, builder, suffix) in enumerate(import_cases(folder)):
        path = folder / f"imp-{index:03d}{suffix}"
        builder(path)
        argv = _fill(case.argv, path, folder)
        if "--array" not in argv:
            argv = (*argv, "--array", str(folder / "array.toml"))
        runs.append(Run(case, ("detect", *argv)))
        runs.append(Run(case, ("localize", *argv)))
        runs.append(Run(case, ("import", *argv, "-o", str(folder / f"imported-{index:03d}.h5"))))
    valid = write_raw_recording(folder / "valid.h5")
    for case in argument_cases():
        runs.append(Run(case, _fill(case.argv, valid, folder)))
    wav = folder / "valid.wav"
    import soundfile

    soundfile.write(str(wav), clean_codes(1)[0].T, int(FS), subtype="PCM_16")
    (folder / "link-target.h5").write_bytes(b"")
    if not os.path.lexists(folder / "link.h5"):
        os.symlink(folder / "link-target.h5", folder / "link.h5")
    for case in output_cases():
        runs.append(Run(case, _fill(case.argv, wav, folder)))
    return runs


def _fill(argv: tuple[str, ...], path: Path, folder: Path) -> tuple[str, ...]:
    return tuple(a.replace("{file}", str(path)).replace("{dir}", str(folder)).replace(
        "{array}", str(folder / "array.toml")) for a in argv)


def classify(expect: str, returncode: int | None, stderr: str, timed_out: bool) -> str:
    """The outcome's kind: "ok" (as expected), "traceback", "hang", "usage" (an argparse usage
    block), "multi-line" (an error over several lines), "accepted" (exit 0 where a refusal was
    expected), "refused" (exit 2 on a valid input), or "crash" (another exit code or a signal)."""
    if timed_out:
        return "hang"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    errors = [line for line in stderr.strip().splitlines() if line.strip()
              and not line.startswith(("binsonar: warning:", "binsonar: note:"))]
    if returncode == 0:
        return "ok" if expect == "accept" else "accepted"
    if returncode == 2:
        if any(line.startswith("usage:") for line in errors):
            return "usage"
        if len(errors) != 1:
            return "multi-line"
        return "ok" if expect == "refuse" else "refused"
    return "crash"
