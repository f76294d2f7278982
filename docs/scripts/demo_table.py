"""Regenerate (or check) the README's demo table from a seed-0 run of the current code.

The table sits between the markers ``<!-- demo-table:start -->`` and ``<!-- demo-table:end -->``
in ``README.md``; it is ``acoustisim.demo.readme_table`` of ``run_demo(DemoConfig())`` (the
thesis tank, 50 pings, seed 0, CA-CFAR, beam-aware localisation), about 15-30 s.

    python docs/scripts/demo_table.py            # rewrite the table in README.md
    python docs/scripts/demo_table.py --check    # exit 1 if README.md's table differs
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"
START, END = "<!-- demo-table:start -->", "<!-- demo-table:end -->"


def current_table() -> str:
    """The table of a seed-0 demo run of this tree."""
    from acoustisim.demo import DemoConfig, readme_table, run_demo

    with tempfile.TemporaryDirectory() as folder:
        return readme_table(run_demo(DemoConfig(), folder, figures=False))


def replace_table(text: str, table: str) -> str:
    """``text`` with the block between the markers replaced by ``table``."""
    head, start, rest = text.partition(START)
    _, end, tail = rest.partition(END)
    if not start or not end:
        raise SystemExit(f"{README}: the markers {START} and {END} are missing")
    return f"{head}{START}\n{table}\n{END}{tail}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if README.md's table differs from a fresh run")
    args = parser.parse_args()
    text = README.read_text()
    new = replace_table(text, current_table())
    if args.check:
        if new != text:
            print(f"{README}: the demo table differs from a seed-0 run; run {Path(__file__).name} to update it")
            return 1
        return 0
    if new != text:
        README.write_text(new)
        print(f"{README}: demo table updated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
