"""Export a log's signals as tables: CSV (one file per component) or one NumPy .npz.

CSV columns: `t_ns` (exact log time [ns]), `t` [s], then one column per variable under its
original name; floats are written with 17 significant digits, so they read back bit for bit.
NPZ keys per component: `<component>.t_ns`, `<component>.t`, `<component>.values` (rows = times,
columns = variables) and `<component>.names`.
Text signals (String and Binary variables, `/text_signals/<component>`): CSV only, one file
`<stem>-<component>-text.csv` per component with columns `t_ns`, `t`, then one per variable, a row
per record (written when a value changes); a String as it is, a Binary as hex digits. The .npz
leaves them out (`--to csv` writes them).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from cosim.errors import CosimError
from cosim.logs.reader import Log
from cosim.record.output import atomic_output, checked_output


def export_signals(
    log: Log, out_dir: Path, fmt: str, components: list[str] | None = None, force: bool = False
) -> list[Path]:
    """Write the signals of `components` (default: all) to `out_dir`; returns the files written.
    Existing files are refused unless `force` (all checked before the first is written)."""
    every = log.components + [name for name in log.text_components if name not in log.components]
    chosen = components or every
    if not chosen:
        raise CosimError(f"{log.path}: no navcosim signal channels to export")
    unknown = [name for name in chosen if name not in every]
    if unknown:
        known = ", ".join(every) or "none"
        raise CosimError(f"{log.path}: no component {', '.join(unknown)} (components: {known})")
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = log.path.stem
    if fmt == "npz":
        if not any(component in log.components for component in chosen):
            raise CosimError(f"{log.path}: {', '.join(chosen)} hold only text signals: --to csv writes them")
        arrays = {}
        for component in (name for name in chosen if name in log.components):
            signals = log.signals(component)
            arrays[f"{component}.t_ns"] = signals.t_ns
            arrays[f"{component}.t"] = signals.t
            arrays[f"{component}.values"] = signals.values
            arrays[f"{component}.names"] = np.array(signals.names, dtype=str)
        path = out_dir / f"{stem}-signals.npz"
        with atomic_output(path, force) as temporary:
            np.savez(temporary, **arrays)
        return [path]
    if fmt == "csv":
        numeric = [component for component in chosen if component in log.components]
        paths = [checked_output(out_dir / f"{stem}-{component}.csv", force) for component in numeric]
        texts = [component for component in chosen if component in log.text_components]
        text_paths = [checked_output(out_dir / f"{stem}-{component}-text.csv", force) for component in texts]
        for component, path in zip(numeric, paths, strict=True):
            with atomic_output(path, force) as temporary:
                _write_csv(log, component, temporary)
        for component, path in zip(texts, text_paths, strict=True):
            with atomic_output(path, force) as temporary:
                _write_text_csv(log, component, temporary)
        return paths + text_paths
    raise CosimError(f"unknown export format {fmt!r} (csv or npz)")


def _write_csv(log: Log, component: str, path: Path) -> Path:
    signals = log.signals(component)
    with open(path, "w", newline="") as handle:
        csv.writer(handle).writerow(["t_ns", "t", *signals.names])
        table = np.column_stack((signals.t, signals.values))
        for t_ns, row in zip(signals.t_ns.tolist(), table, strict=True):
            handle.write(f"{t_ns}," + ",".join(f"{value:.17g}" for value in row.tolist()) + "\n")
    return path


def _write_text_csv(log: Log, component: str, path: Path) -> Path:
    text = log.text_signals(component)
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t_ns", "t", *text.names])
        for t, row in zip(text.t.tolist(), text.rows, strict=True):
            t_ns = round(t * 1e9)
            writer.writerow([t_ns, f"{t:.17g}", *(v.hex() if isinstance(v, bytes) else v for v in row)])
    return path


def read_csv(path: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, t_ns, values) of a CSV written by `export_signals`."""
    with open(path, newline="") as handle:
        header = next(csv.reader(handle))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=float)
    t_ns = np.loadtxt(path, delimiter=",", skiprows=1, usecols=0, ndmin=1, dtype=np.int64)
    return header[2:], t_ns, data[:, 2:]
