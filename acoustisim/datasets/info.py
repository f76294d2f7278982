"""Summarise a dataset store: its card, its shape and its completion."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from acoustisim.datasets.store import DatasetStore


def dataset_info(path: str | Path) -> dict[str, Any]:
    """The card plus the actual completion and array shapes (a JSON-ready dictionary)."""
    store = DatasetStore(path, mode="r")
    card = store.card
    complete = store.complete_mask()
    shape = store.shape
    size = sum(p.stat().st_size for p in store.path.rglob("*") if p.is_file())
    return {
        "path": str(store.path),
        "name": card.get("name"),
        "status": "complete" if complete.all() else "incomplete",
        "n_samples": shape.n_samples,
        "n_complete": int(complete.sum()),
        "n_pings": shape.n_pings,
        "n_time": shape.n_time,
        "max_objects": shape.max_objects,
        "max_arrivals": shape.max_arrivals,
        "samples_per_chunk": shape.chunk_samples,
        "layout_version": card.get("layout_version"),
        "bytes_on_disk": size,
        "code_version": card.get("code_version"),
        "created_utc": card.get("created_utc"),
        "counts": card.get("counts"),
        "snr_histogram": card.get("snr_histogram"),
        "last_run": card.get("last_run"),
        "spec": card.get("spec"),
    }


def format_info(info: dict[str, Any]) -> str:
    """A few human-readable lines."""
    counts = info.get("counts") or {}
    lines = [
        f"{info['path']}: dataset {info['name']!r}, {info['status']}",
        f"  samples: {info['n_complete']} / {info['n_samples']} complete; {info['n_pings']} ping(s) x 3 channels x "
        f"{info['n_time']} time samples (int16)",
        f"  objects: up to {info['max_objects']} per sample; per class: {counts.get('objects_per_class', {})}",
        f"  arrivals: up to {info['max_arrivals']} stored per sample; per kind: {counts.get('arrivals_per_kind', {})}",
        f"  on disk: {info['bytes_on_disk'] / 1e6:.1f} MB in chunks of {info['samples_per_chunk']} samples (layout "
        f"version {info['layout_version']}); code: {info['code_version']}; created {info['created_utc']}",
    ]
    hist = info.get("snr_histogram") or {}
    if hist.get("counts"):
        edges = hist["edges_db"]
        lines.append("  SNR (dB): " + ", ".join(
            f"[{lo:.1f}, {hi:.1f}): {c}" for lo, hi, c in zip(edges[:-1], edges[1:], hist["counts"])))
    return "\n".join(lines)
