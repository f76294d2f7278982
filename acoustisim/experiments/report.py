"""Writing an experiment's outputs: JSON results, PNG figures and a short markdown report."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, tuples and NaN/inf to plain JSON values (NaN -> None)."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def write_json_atomic(path: Path, payload: Any) -> Path:
    """Write JSON to ``path`` via a temporary file and a rename (``binsonar.files``: the umask's
    mode; a link or special file there is refused)."""
    return write_text_atomic(path, json.dumps(to_jsonable(payload), indent=2, sort_keys=False) + "\n")


def write_text_atomic(path: Path, text: str) -> Path:
    """Write text to ``path`` via a temporary file and a rename (``binsonar.files``)."""
    from binsonar.files import write_text_atomic as write_atomically

    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomically(path, text, option="")


@dataclass
class ExperimentReport:
    """Accumulates an experiment's results, figures and text, then writes them to ``out_dir``.

    Files: ``results.json``, ``report.md`` and the figures (PNG) named in ``figures``.
    """

    name: str
    out_dir: Path
    results: dict[str, Any] = field(default_factory=dict)
    figures: list[tuple[str, str]] = field(default_factory=list)
    sections: list[str] = field(default_factory=list)

    def add_figure(self, figure: Any, filename: str, caption: str) -> Path:
        """Save a matplotlib figure as PNG in the output folder and list it in the report."""
        import matplotlib.pyplot as plt

        self.out_dir.mkdir(parents=True, exist_ok=True)
        path = self.out_dir / filename
        figure.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(figure)
        self.figures.append((filename, caption))
        return path

    def add_section(self, markdown: str) -> None:
        """Append a markdown paragraph or table to the report."""
        self.sections.append(markdown.strip())

    def write(self) -> dict[str, str]:
        """Write results.json and report.md; returns the paths written."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        payload = {"experiment": self.name, **self.results,
                   "figures": [name for name, _ in self.figures]}
        json_path = write_json_atomic(self.out_dir / "results.json", payload)
        lines = [f"# Experiment `{self.name}`", ""]
        for section in self.sections:
            lines += [section, ""]
        for name, caption in self.figures:
            lines += [f"![{caption}]({name})", "", f"*{caption}*", ""]
        md_path = write_text_atomic(self.out_dir / "report.md", "\n".join(lines))
        return {"results": str(json_path), "report": str(md_path)}


def markdown_table(header: list[str], rows: list[list[Any]]) -> str:
    """A markdown table; floats shown with 4 significant digits."""

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return "n/a" if not math.isfinite(v) else f"{v:.4g}"
        return str(v)

    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(out)
