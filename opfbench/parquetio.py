"""The one parquet writer: every parquet file opfbench writes goes through it, atomically
(a temporary file in the same folder, then rename), so a reader — or a resumed run —
never sees half a file.

Categorical columns are written as plain text (the files hold text; categoricals only
make building and handing over the long tables fast). `metadata` adds key-value pairs to
the file's schema (a checkpoint's task, `opfbench.study.store`).
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from opfbench.jsonio import write_atomic


def arrow_table(frame: pd.DataFrame | pa.Table, metadata: dict[bytes, bytes] | None = None) -> pa.Table:
    """`frame` as an arrow table (no index), dictionary columns as their values, with
    `metadata` (None: the table's own, pandas' schema note only)."""
    table = frame if isinstance(frame, pa.Table) else pa.Table.from_pandas(frame, preserve_index=False)
    fields = [pa.field(f.name, f.type.value_type) if pa.types.is_dictionary(f.type) else f for f in table.schema]
    if fields != list(table.schema):
        table = table.cast(pa.schema(fields, metadata=table.schema.metadata))
    if metadata is not None:
        pandas_note = {k: v for k, v in (table.schema.metadata or {}).items() if k == b"pandas"}
        table = table.replace_schema_metadata(pandas_note | metadata)
    return table


def write_parquet(path: str | Path, frame: pd.DataFrame | pa.Table, metadata: dict[bytes, bytes] | None = None) -> Path:
    """Write `frame` to `path` atomically (see `arrow_table` for `metadata`)."""
    buf = io.BytesIO()
    pq.write_table(arrow_table(frame, metadata), buf)
    return write_atomic(path, buf.getvalue())


class ParquetStream:
    """A parquet file written table by table into a temporary file beside `path`
    (`.NAME.PID.tmp`), renamed onto `path` by `commit`; `abort` drops it. Every table is
    cast to the first one's schema (written without metadata: the file's tables come from
    many sources)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        self.writer: pq.ParquetWriter | None = None

    def write(self, frame: pd.DataFrame | pa.Table) -> None:
        table = arrow_table(frame, {})
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.tmp, table.schema)
        self.writer.write_table(table.cast(self.writer.schema))

    def commit(self) -> None:
        """Close and rename (nothing written: no file)."""
        if self.writer is not None:
            self.writer.close()
            self.writer = None
            os.replace(self.tmp, self.path)

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        self.tmp.unlink(missing_ok=True)
