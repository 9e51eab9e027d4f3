"""What a sweep leaves in its folder, and what a rerun reads back.

- cases.parquet: one row per case (Apache Parquet, via pyarrow): its key, index, the varied values,
  status, message, wall time, last time, final / min / max of each recorded column and the metrics.
  Rewritten whole (to a temporary file, then renamed) every few seconds and at the end, so an
  interrupted sweep keeps what it finished and a reader never sees half a file.
- series.zarr (with --series): every case's recorded rows, one variable per column with dimensions
  (case, time), opened by `xarray.open_zarr`. Zarr because cases are appended along `case` as they
  finish, without rewriting earlier ones (netCDF/HDF5 files are rewritten or locked), chunked one
  case per chunk, and readable by many processes and from object stores. Format 2 with
  consolidated metadata: what every Zarr reader opens without a warning. A case that stopped
  early has NaN after its last row.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from master.recorder import number_columns

CASES = "cases.parquet"
SERIES = "series.zarr"


def read_cases(folder: Path) -> list[dict]:
    """The rows of an earlier run of the sweep in `folder` (none if there is no table)."""
    import pyarrow.parquet as pq

    path = folder / CASES
    if not path.exists():
        return []
    try:
        return pq.read_table(path).to_pylist()
    except Exception as e:  # pyarrow raises its own error types for a damaged file
        raise OSError(f"{path}: cannot be read ({e}); move it away to start the sweep afresh") from None


def write_cases(folder: Path, rows: list[dict], columns: list[str]) -> None:
    """All rows, in `columns` order, replacing the table atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({c: [r.get(c) for r in rows] for c in columns})
    path = folder / CASES
    tmp = path.with_name(f".{CASES}.{os.getpid()}.tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def series_keys(folder: Path) -> set[str]:
    """Keys of the cases whose series the store already holds."""
    path = folder / SERIES
    if not path.exists():
        return set()
    import xarray as xr

    with xr.open_zarr(path) as ds:
        return {str(k) for k in ds["case"].values}


def append_series(
    folder: Path, time: np.ndarray, keys: list[str], rows: list[np.ndarray], varied: dict[str, list[float]]
) -> None:
    """Append cases (their keys, recorded rows and varied values) to the series store along `case`."""
    import xarray as xr

    if not keys:
        return
    names = number_columns(rows[0])
    data = {}
    for n in names:
        block = np.full((len(keys), len(time)), math.nan)
        for i, r in enumerate(rows):
            m = min(len(r), len(time))
            block[i, :m] = r[n][:m]
        data[n] = (("case", "time"), block)
    coords = {"case": np.array(keys, dtype=object), "time": time}
    coords.update(
        {
            name: ("case", np.asarray(values, dtype=float))
            for name, values in varied.items()
            if name not in data
        }
    )
    ds = xr.Dataset(data, coords=coords)
    path = folder / SERIES
    if path.exists():
        ds.to_zarr(path, append_dim="case")
    else:
        chunks = {n: {"chunks": (1, len(time))} for n in names}
        ds.to_zarr(path, mode="w-", zarr_format=2, encoding=chunks)
