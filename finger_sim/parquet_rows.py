"""A sweep's or sample's rows as Parquet (pyarrow), beside the CSV: typed columns, compressed, and
read by pandas, polars, DuckDB or Spark without parsing text."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from finger_sim.errors import ConfigError


def write_parquet(path: Path, header: Sequence[str], rows: Sequence[dict[str, Any]]) -> None:
    """The rows as one Parquet table, columns in `header` order: the varied keys as the text
    they were given in (as in the CSV), the results as float64."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ConfigError("--parquet", "pyarrow installed (pip install 'finger_sim[cluster]')", "not installed") from None
    table = pa.table({c: [row[c] for row in rows] for c in header})
    pq.write_table(table, path)
