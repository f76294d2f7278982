"""Line counts of ``acoustisim/propagation``: the reference engine, the fast engine and the
shared modules of this tree (or ``--tree DIR``), against the whole package of an older checkout
(``--before-tree DIR``, e.g. the pre-session tree, whose package had no engines).

Counts physical lines of ``*.py`` files (blank lines, comments and docstrings included), as
``wc -l`` does.

Run: ``python benchmarks/propagation_lines.py [--tree DIR] [--before-tree DIR]``
"""

from __future__ import annotations

import argparse
from pathlib import Path


def line_count(files: list[Path]) -> int:
    """Physical lines over ``files`` (``wc -l``: newline characters)."""
    return sum(path.read_bytes().count(b"\n") for path in files)


def package_parts(package: Path) -> dict[str, list[Path]]:
    """The ``*.py`` files of a propagation package by part: ``reference/``, ``fast/`` and the
    rest (the shared modules; every file for a package without engines)."""
    everything = sorted(package.rglob("*.py"))
    parts = {name: [path for path in everything if path.relative_to(package).parts[0] == name]
             for name in ("reference", "fast")}
    engines = set(parts["reference"]) | set(parts["fast"])
    parts["rest"] = [path for path in everything if path not in engines]
    return parts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--tree", default=str(Path(__file__).resolve().parents[1]))
    parser.add_argument("--before-tree", default=None)
    args = parser.parse_args()
    for label, root in (("now", args.tree), ("before", args.before_tree)):
        if root is None:
            continue
        package = Path(root) / "acoustisim" / "propagation"
        parts = package_parts(package)
        total = sum(line_count(files) for files in parts.values())
        n_files = sum(len(files) for files in parts.values())
        shown = ", ".join(f"{name}/ {line_count(files)} lines in {len(files)} files" if name != "rest" else
                          f"the rest {line_count(files)} lines in {len(files)} files"
                          for name, files in parts.items() if files)
        print(f"{label} ({package}): {total} lines in {n_files} files: {shown}")


if __name__ == "__main__":
    main()
