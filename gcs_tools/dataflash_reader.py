"""Read an ArduPilot DataFlash log (.bin) into numpy: every message type a structured
array, fast, and without giving up on damage.

The format is ArduPilot's (``libraries/AP_Logger``; pymavlink's ``DFReader`` reads it
message by message): each message is ``0xA3 0x95``, a type byte and a fixed-size
payload, and the ``FMT`` messages (type 128, the first in the file) give each type's
name, length, field letters and column names. :mod:`gcs_tools.log_scan` finds the
messages in one compiled pass (learning the lengths from the FMT messages as it meets
them); each type's rows are then gathered at once and viewed as a structured array.
Scaled letters (``c``/``C``/``e``/``E``: hundredths, ``L``: 1e-7 degrees) are scaled by
:meth:`DataFlash.column`, as pymavlink does. Damage (bytes that are not a message of a
known type, a truncated end) is skipped and counted in
:class:`~gcs_tools.tlog_reader.ReadStats`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gcs_tools.log_scan import DATAFLASH_FMT, gather, scan_dataflash
from gcs_tools.tlog_reader import ReadStats

MAGIC = bytes([0xA3, 0x95, DATAFLASH_FMT])  # a DataFlash log starts with an FMT message
HEADER_BYTES = 3
# Field letter -> (numpy type, scale): pymavlink's DFReader.FORMAT_TO_STRUCT.
LETTERS: dict[str, tuple[str | tuple[str, tuple[int]], float | None]] = {
    "a": (("<i2", (32,)), None),
    "b": ("i1", None),
    "B": ("u1", None),
    "g": ("<f2", None),
    "h": ("<i2", None),
    "H": ("<u2", None),
    "i": ("<i4", None),
    "I": ("<u4", None),
    "f": ("<f4", None),
    "d": ("<f8", None),
    "n": ("S4", None),
    "N": ("S16", None),
    "Z": ("S64", None),
    "c": ("<i2", 0.01),
    "C": ("<u2", 0.01),
    "e": ("<i4", 0.01),
    "E": ("<u4", 0.01),
    "L": ("<i4", 1e-7),
    "M": ("u1", None),
    "q": ("<i8", None),
    "Q": ("<u8", None),
}
INSTANCE_COLUMNS = ("I", "C", "Inst", "Instance")  # which sensor, EKF core or battery


@dataclass
class Format:
    name: str
    length: int  # whole message, header included
    letters: str
    columns: tuple[str, ...]
    dtype: np.dtype
    scales: dict[str, float]


@dataclass
class DataFlash:
    """A DataFlash log's content: :meth:`table`, a message's rows (structured, raw
    units; :meth:`column` scales them), read from the file's bytes when first asked
    for (a replay uses a fifth of a copter log's message types)."""

    formats: dict[str, Format]
    stats: ReadStats
    warnings: list[str] = field(default_factory=list)
    data: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8), repr=False)
    located: dict[str, np.ndarray] = field(default_factory=dict, repr=False)  # payloads
    read: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def names(self) -> list[str]:
        """The message types the log holds rows of."""
        return sorted(self.located)

    def rows(self, name: str) -> np.ndarray | None:
        """Every row of message ``name`` (None if the log has none)."""
        if name not in self.read:
            offsets = self.located.get(name)
            if offsets is None:
                return None
            fmt = self.formats[name]
            payload = fmt.length - HEADER_BYTES
            self.read[name] = gather(self.data, offsets, payload, payload).view(fmt.dtype).ravel()
        return self.read[name]

    def table(self, name: str, instance: int | None = 0) -> np.ndarray | None:
        """The rows of message ``name`` (those of ``instance`` where it has an
        instance column; None: all), or None if the log has none."""
        rows = self.rows(name)
        if rows is None or len(rows) == 0:
            return None
        column = next((c for c in INSTANCE_COLUMNS if c in (rows.dtype.names or ())), None)
        if instance is not None and column is not None:
            rows = rows[rows[column] == instance]
        return rows if len(rows) else None

    def column(self, name: str, rows: np.ndarray, column: str) -> np.ndarray:
        """``rows[column]`` of message ``name`` in float64, scaled as its letter says."""
        scale = self.formats[name].scales.get(column)
        values = rows[column].astype(np.float64)
        return values * scale if scale is not None else values

    def end_us(self) -> int:
        """The latest TimeUS of the log (µs since boot; 0 without one)."""
        ends = [
            int(rows["TimeUS"].max())
            for rows in map(self.rows, self.names)
            if rows is not None and len(rows) and "TimeUS" in (rows.dtype.names or ())
        ]
        return max(ends, default=0)


def read_dataflash(path: str | Path) -> DataFlash:
    """The DataFlash log at ``path``; ValueError if it does not start as one."""
    data = np.fromfile(path, dtype=np.uint8)
    if bytes(data[: len(MAGIC)]) != MAGIC:
        raise ValueError(f"{path} is not an ArduPilot DataFlash log (no FMT message first)")
    records, skipped, truncated = scan_dataflash(data)
    log = DataFlash({}, ReadStats(skipped_bytes=skipped, truncated=truncated), data=data)
    by_type = _formats(data, records[records[:, 1] == DATAFLASH_FMT, 0], log)
    kinds = records[:, 1]
    order = np.argsort(kinds, kind="stable")
    types, starts = np.unique(kinds[order], return_index=True)
    for kind, rows in zip(types.tolist(), np.split(order, starts[1:]), strict=True):
        fmt = by_type.get(kind)
        if fmt is not None and kind != DATAFLASH_FMT:
            log.located[fmt.name] = records[rows, 0] + HEADER_BYTES
    log.stats.messages = len(records)
    return log


def _formats(data: np.ndarray, offsets: np.ndarray, log: DataFlash) -> dict[int, Format]:
    """The message formats the FMT messages define, by type (the last one for a type
    redefined); an FMT this reader cannot use is a warning, its messages left out."""
    fmt_dtype = np.dtype([("type", "u1"), ("length", "u1"), ("name", "S4"), ("format", "S16"),
                          ("columns", "S64")])  # fmt: skip
    rows = gather(data, offsets + HEADER_BYTES, fmt_dtype.itemsize, fmt_dtype.itemsize)
    by_type: dict[int, Format] = {}
    for row in rows.view(fmt_dtype).ravel():
        name = row["name"].decode("ascii", "replace").rstrip("\x00")
        letters = row["format"].decode("ascii", "replace").rstrip("\x00")
        columns = tuple(row["columns"].decode("ascii", "replace").rstrip("\x00").split(","))
        try:
            fmt = _format(name, int(row["length"]), letters, columns)
        except (KeyError, ValueError) as error:
            log.warnings.append(f"message {name}: {error}; left out")
            continue
        by_type[int(row["type"])] = fmt
        log.formats[name] = fmt
    return by_type


def _format(name: str, length: int, letters: str, columns: tuple[str, ...]) -> Format:
    if len(letters) != len(columns):
        raise ValueError(f"{len(letters)} field letters for {len(columns)} columns")
    fields = []
    scales: dict[str, float] = {}
    for letter, column in zip(letters, columns, strict=True):
        numpy_type, scale = LETTERS[letter]
        fields.append(
            (column, *numpy_type) if isinstance(numpy_type, tuple) else (column, numpy_type)
        )
        if scale is not None:
            scales[column] = scale
    dtype = np.dtype(fields)
    if dtype.itemsize != length - HEADER_BYTES:
        raise ValueError(f"its fields take {dtype.itemsize} bytes, its length says {length - 3}")
    return Format(name, length, letters, columns, dtype, scales)
