"""``binsonar detect`` on long recordings: time per ping and peak memory against the detector's own
time, measured in the same run.

Usage
-----
    python benchmarks/bench_recording.py [--pings 10 1000] [--methods matched] [--repeats 3]
        [--samples 250000] [--baseline /work/wt/baseline --baseline-pings 10 100]

Recordings of the thesis tank's size (3 x ``--samples`` int16 codes per ping at 20 MS/s, a
12-bit ADC; two echoes per channel in noise, 10 different pings repeated) are written with
``write_recording_chunks`` for each ``--pings`` count (1,000 pings: 1.5 GB, in a temporary
folder removed afterwards). For each method and file, ``python -m binsonar.cli.main detect FILE
--method M --json`` runs in its own process ``--repeats`` times; reported (medians):

- ``wall``: the command's wall time, and per ping;
- ``detector``: the detector's own time per ping, from the same run's JSON ``elapsed_s`` (the
  detection's validation, set-up and filtering, without file reading; summed over pings);
- ``marginal``: (wall at the largest count - wall at the smallest) / (difference in pings): the
  command's cost of one more ping, without the start-up (imports, planning, the kernels' first
  compilation) both runs pay; against the detector's own marginal time per ping (the same
  difference of ``elapsed_s``), the ratio is the goal (issue 19: at most 1.5);
- ``peak RSS``: the process's peak resident memory (``wait4``'s ``ru_maxrss``): it must not grow
  with the number of pings.

``--baseline ROOT`` runs another checkout's ``binsonar detect`` on ``--baseline-pings`` counts
(its reader holds the whole file as float64 volts: 1,000 pings would need 7.5 GB).
``--open-pings N`` (default 41, the issue's file) also times ``read_recording(path,
keep_codes=True)`` against one raw h5py read of the same dataset, in a fresh process each.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FS = 20e6
STEP = 5.0 / 4096  # a 12-bit ADC over +/-2.5 V
DISTINCT = 10


def make_pings(n_samples: int, seed: int = 0) -> np.ndarray:
    """``DISTINCT`` pings (DISTINCT, 3, n) of int16 codes: two echoes per channel in white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / FS
    volts = rng.normal(0.0, 0.01, (DISTINCT, 3, n_samples))
    for channel, delay in enumerate((2.0e-3, 1.999e-3, 2.001e-3)):
        for amplitude, extra in ((0.3, 0.0), (0.15, 1.5e-3)):
            tau = t - delay - extra
            volts[:, channel] += amplitude * np.exp(-13.8 * tau ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * tau)
    return np.clip(np.round(volts / STEP), -2047, 2047).astype(np.int16)


def pulse() -> np.ndarray:
    t = (np.arange(201) - 100) / FS
    return np.exp(-13.8 * t ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * t)


def write_file(path: Path, pings: np.ndarray, n_pings: int) -> Path:
    """A recording of ``n_pings`` pings cycling through ``pings``, written range by range."""
    from binsonar.recording import Recording, Template, write_recording_chunks

    template = Template(pulse(), FS, -100 / FS)

    def chunks():
        for start in range(0, n_pings, DISTINCT):
            count = min(DISTINCT, n_pings - start)
            yield Recording(None, FS, 0.0, codes=pings[:count], volts_per_code=STEP, adc_bits=12,
                            template=template, sound_speed_m_s=1482.0)

    return write_recording_chunks(path, chunks(), n_pings, store_codes=True)


def run_detect(root: Path, path: Path, method: str) -> dict[str, float]:
    """One ``binsonar detect`` process: wall time, peak RSS and the detector's own time."""
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONWARNINGS": "ignore"}
    start = time.perf_counter()
    process = subprocess.Popen([sys.executable, "-m", "binsonar.cli.main", "detect", str(path), "--method", method,
                                "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=root)
    stdout_chunks = []
    while True:
        block = process.stdout.read(1 << 20)
        if not block:
            break
        stdout_chunks.append(block)
    stderr = process.stderr.read()
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise RuntimeError(f"detect failed ({process.returncode}): {stderr.decode()[-400:]}")
    report = json.loads(b"".join(stdout_chunks))
    return {"wall_s": wall, "peak_rss_mb": usage.ru_maxrss / 1024.0, "detector_s": float(report["elapsed_s"]),
            "n_pings": int(report["n_pings"])}


OPEN_CODE = """
import resource, sys, time
import h5py, numpy
from binsonar.recording import read_recording
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
if sys.argv[2] == "raw":
    with h5py.File(sys.argv[1], "r") as h5:
        data = h5["waveforms"][()]
else:
    data = read_recording(sys.argv[1], keep_codes=True)
elapsed = time.perf_counter() - start
print(elapsed, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024.0)  # KB on Linux
"""


def run_open(root: Path, path: Path, how: str) -> tuple[float, float]:
    """One read of ``path`` in a fresh process, ``how`` "raw" (h5py, the dataset whole) or
    "recording" (``read_recording(path, keep_codes=True)``): (seconds, MB the read added to the
    process's peak memory)."""
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONWARNINGS": "ignore"}
    out = subprocess.run([sys.executable, "-c", OPEN_CODE, str(path), how], capture_output=True, text=True, env=env,
                         cwd=root, check=True)
    seconds, memory = (float(v) for v in out.stdout.split())
    return seconds, memory


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pings", type=int, nargs="+", default=[10, 1000])
    parser.add_argument("--methods", nargs="+", default=["matched"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--samples", type=int, default=250_000)
    parser.add_argument("--baseline", type=Path, default=None, help="another checkout to time on --baseline-pings")
    parser.add_argument("--baseline-pings", type=int, nargs="+", default=[10, 100])
    parser.add_argument("--folder", type=Path, default=None, help="where to write the recordings (default a temp dir)")
    parser.add_argument("--write-only", type=Path, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--open-pings", type=int, default=41,
                        help="also time read_recording(keep_codes=True) on this many pings (the issue's 41); 0: skip")
    args = parser.parse_args()
    counts = sorted(set(args.pings) | (set(args.baseline_pings) if args.baseline else set())
                    | ({args.open_pings} if args.open_pings else set()))
    if args.write_only is not None:
        pings = make_pings(args.samples)
        for n in counts:
            t = time.perf_counter()
            path = write_file(args.write_only / f"pings-{n}.h5", pings, n)
            print(f"wrote {n} pings ({path.stat().st_size / 1e6:.0f} MB) in {time.perf_counter() - t:.1f} s", flush=True)
        return 0
    with tempfile.TemporaryDirectory(prefix="bench-recording-", dir=args.folder) as folder:
        # Written by a child process: Linux keeps a process's peak RSS across fork and exec, so
        # this process stays small for the children's peaks to be their own.
        subprocess.run([sys.executable, __file__, "--write-only", folder, "--samples", str(args.samples), "--pings",
                        *map(str, counts), "--open-pings", "0"], check=True)
        files = {n: Path(folder) / f"pings-{n}.h5" for n in counts}
        roots = [("this checkout", ROOT, args.pings)]
        if args.baseline is not None:
            roots.append(("baseline", args.baseline.resolve(), args.baseline_pings))
        if args.open_pings:
            print(f"\nread_recording(keep_codes=True) of {args.open_pings} pings (medians of {args.repeats}):")
            for label, root, _ in roots:
                for how in ("raw", "recording"):
                    runs = [run_open(root, files[args.open_pings], how) for _ in range(args.repeats)]
                    seconds, memory = (statistics.median(r[k] for r in runs) for k in range(2))
                    name = "raw h5py read" if how == "raw" else "read_recording"
                    print(f"{label:14s} {name:15s} {seconds * 1e3:8.1f} ms, {memory:6.0f} MB added to the peak")
        for method in args.methods:
            print(f"\nbinsonar detect --method {method} --json ({args.samples} samples x 3 channels per ping; "
                  f"medians of {args.repeats})")
            print(f"{'checkout':14s} {'pings':>6s} {'wall s':>8s} {'wall/ping ms':>13s} {'detector/ping ms':>17s} "
                  f"{'peak RSS MB':>12s}")
            for label, root, ping_counts in roots:
                rows = {}
                for n in ping_counts:
                    runs = [run_detect(root, files[n], method) for _ in range(args.repeats)]
                    rows[n] = {key: statistics.median(r[key] for r in runs) for key in runs[0]}
                    row = rows[n]
                    print(f"{label:14s} {n:6d} {row['wall_s']:8.2f} {row['wall_s'] / n * 1e3:13.2f} "
                          f"{row['detector_s'] / row['n_pings'] * 1e3:17.2f} {row['peak_rss_mb']:12.0f}", flush=True)
                if len(ping_counts) >= 2:
                    low, high = min(ping_counts), max(ping_counts)
                    marginal = (rows[high]["wall_s"] - rows[low]["wall_s"]) / (high - low)
                    detector = (rows[high]["detector_s"] - rows[low]["detector_s"]) / (high - low)
                    print(f"{label:14s} one more ping costs {marginal * 1e3:.2f} ms from the command line and "
                          f"{detector * 1e3:.2f} ms in the detector (its first-call compilation and planning "
                          f"excluded alike): ratio {marginal / detector:.2f}; peak RSS "
                          f"{rows[low]['peak_rss_mb']:.0f} MB at {low} pings, {rows[high]['peak_rss_mb']:.0f} MB at "
                          f"{high}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
