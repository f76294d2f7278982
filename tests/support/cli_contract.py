"""The command-line contract for any input, and ways to run commands against it.

Contract: exit 0, or exit 2 with exactly one line on stderr (no traceback, no usage block, no
"out of memory": the pre-flight must refuse a job before it runs out), within a time limit.

- :func:`run_in_process` runs ``acoustisim`` or ``binsonar`` in this process (fast: for the
  fuzz suite), under a ``SIGALRM`` watchdog that turns a run past its time into a failure.
- :func:`run_guarded` runs a batch of commands in one child process with an address-space
  limit (``RLIMIT_AS``) and a wall-clock timeout, for the inputs that could hang or
  allocate without bound (a FIFO, ``/dev/zero``, 10^9 pings).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Run:
    """One command's result."""

    argv: tuple[str, ...]
    code: int
    out: str
    err: str
    seconds: float


class RunTimeout(Exception):
    """A command ran past its time limit."""


@contextlib.contextmanager
def _watchdog(seconds: float) -> Iterator[None]:
    def expire(signum, frame):  # noqa: ANN001 - signal handler signature
        raise RunTimeout(f"past {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def run_in_process(argv: Sequence[str], program: str = "acoustisim", timeout_s: float = 60.0) -> Run:
    """Run a command's ``main`` here, capturing stdout and stderr; an escaping exception (a
    traceback on the command line) propagates to the test."""
    if program == "acoustisim":
        from acoustisim.cli.main import main
    else:
        from binsonar.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    with _watchdog(timeout_s), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return Run(tuple(argv), int(code), out.getvalue(), err.getvalue(), time.perf_counter() - start)


def check_contract(run: Run) -> None:
    """Assert the contract: exit 0, or exit 2 with one stderr line (and nothing on stdout)."""
    assert run.code in (0, 2), f"{run.argv}: exit {run.code}\n{run.err}"
    assert "Traceback" not in run.err, f"{run.argv}: traceback\n{run.err}"
    assert "out of memory" not in run.err, f"{run.argv}: ran out of memory instead of a pre-flight refusal"
    if run.code == 2:
        lines = run.err.splitlines()
        assert len(lines) == 1 and lines[0].strip(), f"{run.argv}: expected one line, got\n{run.err}"
        assert not lines[0].startswith("usage:"), f"{run.argv}: usage block\n{run.err}"
        assert run.out == "", f"{run.argv}: output on a refusal\n{run.out}"


_DRIVER = """
import contextlib, io, json, resource, sys, time
limit = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
from acoustisim.cli.main import main as acoustisim
from binsonar.cli.main import main as binsonar
results = []
for program, argv in json.loads(sys.stdin.read()):
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = (acoustisim if program == "acoustisim" else binsonar)(argv)
    except BaseException as exc:  # the contract failed: report it, keep going
        import traceback
        code, err = -1, io.StringIO("Traceback (most recent call last):\\n" + traceback.format_exc())
    results.append([argv, code, out.getvalue(), err.getvalue(), time.perf_counter() - start])
    print(json.dumps(results[-1]), flush=True)
"""


def run_guarded(commands: Sequence[tuple[str, Sequence[str]]], cwd: Path, *, timeout_s: float = 120.0,
                memory_gb: float = 6.0) -> list[Run]:
    """Run ``(program, argv)`` commands in one child process limited to ``memory_gb`` of address
    space and ``timeout_s`` of wall time in all. A command that does not finish in time shows as
    exit code -9 (the rest of the batch is not run)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ACOUSTISIM_MAX_")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + str(ROOT / "tests")
    env["MPLBACKEND"] = "Agg"
    payload = json.dumps([[program, list(argv)] for program, argv in commands])
    process = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, str(int(memory_gb * 2**30))], cwd=cwd, env=env, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        stdout, _ = process.communicate(payload, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        stdout, _ = process.communicate()
    runs = [Run(tuple(argv), code, out, err, seconds)
            for argv, code, out, err, seconds in (json.loads(line) for line in stdout.splitlines() if line.strip())]
    for program, argv in commands[len(runs):]:
        runs.append(Run(tuple(argv), -9, "", f"did not finish within {timeout_s} s", timeout_s))
    return runs


__all__ = ("Run", "RunTimeout", "check_contract", "run_guarded", "run_in_process")
