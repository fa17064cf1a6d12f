"""Reading a finished run's outputs: ``summary.json``, ``timeseries.csv``, ``tracks.csv``.

The CSV readers return a numpy structured array (one field per column: ``int64`` when every
value of the column is an integer, ``float64`` otherwise, an empty cell read as NaN), or a
pandas ``DataFrame`` with ``pandas=True`` (pandas is optional and only imported then).
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["read_summary", "read_timeseries", "read_tracks", "read_csv", "track_of"]



def read_summary(out: str | os.PathLike[str]) -> dict[str, Any]:
    """``OUT/summary.json`` as a dict (``violations``, ``ua_final``, ``agents`` with each
    UAV's ``external_decisions`` and ``external_fallbacks``, ...)."""
    with open(Path(out) / "summary.json", encoding="utf-8") as f:
        return json.load(f)


def _column(values: list[str]) -> np.ndarray:
    """A CSV column as ``int64`` if every value is an integer, else ``float64``, else text."""
    try:
        return np.array([int(v) for v in values], dtype=np.int64)
    except ValueError:
        pass
    try:
        return np.array([float(v) if v != "" else np.nan for v in values], dtype=np.float64)
    except ValueError:
        return np.array(values, dtype=object)


def read_csv(path: str | os.PathLike[str], pandas: bool = False) -> Any:
    """A CSV file with a header row as a numpy structured array (or a pandas DataFrame)."""
    if pandas:
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("pandas=True needs pandas installed (pip install pandas)") from e
        return pd.read_csv(path)
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ValueError(f"{path} is empty")
    names = rows[0]
    body = [r for r in rows[1:] if r]
    cols = [_column([r[i] if i < len(r) else "" for r in body]) for i in range(len(names))]
    dtype = np.dtype([(n, c.dtype) for n, c in zip(names, cols)])
    out = np.empty(len(body), dtype=dtype)
    for n, c in zip(names, cols):
        out[n] = c
    return out


def read_timeseries(out: str | os.PathLike[str], pandas: bool = False) -> Any:
    """``OUT/timeseries.csv``: one row per step (``step``, ``time_s``, ``ua``,
    ``violations``, ...)."""
    return read_csv(Path(out) / "timeseries.csv", pandas=pandas)


def read_tracks(out: str | os.PathLike[str], pandas: bool = False) -> Any:
    """``OUT/tracks.csv``: every UAV's true pose at every step (``step``, ``time_s``, ``uav``,
    ``x``, ``y``, ``z``, ``yaw``)."""
    return read_csv(Path(out) / "tracks.csv", pandas=pandas)


def track_of(tracks: np.ndarray, uav: int) -> np.ndarray:
    """The rows of one UAV of :func:`read_tracks`'s array, ordered by step."""
    rows = tracks[tracks["uav"] == uav]
    return rows[np.argsort(rows["step"], kind="stable")]
