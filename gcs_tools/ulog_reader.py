"""Read a PX4 ULog (.ulg) into numpy: every topic a structured array, fast, and without
giving up on damage.

The format is PX4's ("ULog File Format" in PX4's developer guide): a 16-byte header
(``ULog`` magic, version, start time), a definitions section (formats ``F``, info
``I``/``M``, parameters ``P``/``Q``, flag bits ``B``), then a data section of
subscriptions ``A`` and their data ``D``, log messages ``L``/``C``, parameter changes
``P``, sync ``S`` and dropouts ``O``. Every message starts with its payload size
(uint16) and type (one ASCII letter).

:mod:`gcs_tools.log_scan` finds the messages in one compiled pass; each topic's ``D``
payloads are then gathered at once and viewed as a numpy structured array built from its
format (nested formats become nested fields, ``float[4] q`` a (rows, 4) field), so the
reader's speed is numpy's. Damage (a header no ULog message has, a ``D`` of an unknown
subscription or the wrong size, a truncated end) is counted in
:class:`~gcs_tools.tlog_reader.ReadStats` and the rest is read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs_tools.log_scan import ULOG_DATA, gather, scan_ulog
from gcs_tools.tlog_reader import ReadStats

MAGIC = b"ULog\x01\x12\x35"
HEADER_BYTES = 16  # magic (7), version (1), timestamp (8)
BASIC = {
    "int8_t": "i1",
    "uint8_t": "u1",
    "int16_t": "<i2",
    "uint16_t": "<u2",
    "int32_t": "<i4",
    "uint32_t": "<u4",
    "int64_t": "<i8",
    "uint64_t": "<u8",
    "float": "<f4",
    "double": "<f8",
    "bool": "u1",
    "char": "S1",
}
FIELD = re.compile(r"^(\w+)(?:\[(\d+)\])?$")  # ``float[3]`` -> (float, 3)
INCOMPAT_DATA_APPENDED = 1  # the only incompatible flag this reader knows


@dataclass
class ULog:
    """A ULog's content. :meth:`topic`: a topic's rows (structured, with a
    ``timestamp`` field in µs since boot), read from the file's bytes when first asked
    for; ``messages``: (µs, MAV_SEVERITY-style level 0..7, text); ``parameter_changes``:
    (µs, name, value), after the initial ``parameters``; ``dropouts``: (µs, ms lost)."""

    start_us: int  # µs since boot: the header's
    info: dict[str, Any]
    parameters: dict[str, float]
    parameter_changes: list[tuple[int, str, float]]
    messages: list[tuple[int, int, str]]
    dropouts: list[tuple[int, int]]
    stats: ReadStats
    warnings: list[str] = field(default_factory=list)
    end_us: int = 0  # µs since boot: the latest time stamp of the log's data
    data: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8), repr=False)
    located: dict[tuple[str, int], _Located] = field(default_factory=dict, repr=False)
    read: dict[tuple[str, int], np.ndarray] = field(default_factory=dict, repr=False)

    def topic(self, name: str, multi_id: int = 0) -> np.ndarray | None:
        """The rows of topic ``name`` (instance ``multi_id``), None if the log has none."""
        key = (name, multi_id)
        if key not in self.read:
            where = self.located.get(key)
            if where is None:
                return None
            self.read[key] = where.rows(self.data)
        rows = self.read[key]
        return rows if len(rows) else None

    @property
    def topic_names(self) -> list[tuple[str, int]]:
        """(name, multi id) of every topic with data."""
        return sorted(self.located)


@dataclass
class _Located:
    """Where a topic's data messages are: payload offsets (file order) and sizes."""

    offsets: np.ndarray
    sizes: np.ndarray
    dtype: np.dtype

    def rows(self, data: np.ndarray) -> np.ndarray:
        """Gathered (one copy per distinct size: PX4 may leave out trailing padding) and
        viewed as the topic's structured type, in file order."""
        itemsize = self.dtype.itemsize
        table = np.zeros((len(self.offsets), itemsize), dtype=np.uint8)
        for size in np.unique(self.sizes):
            same = self.sizes == size
            table[same] = gather(data, self.offsets[same], int(size), itemsize)
        return table.view(self.dtype).ravel()


def is_ulog(path: str | Path) -> bool:
    with open(path, "rb") as f:
        return f.read(len(MAGIC)) == MAGIC


def read_ulog(path: str | Path) -> ULog:
    """The ULog at ``path``; ValueError if it does not start as one."""
    data = np.fromfile(path, dtype=np.uint8)
    if bytes(data[: len(MAGIC)]) != MAGIC or len(data) < HEADER_BYTES:
        raise ValueError(f"{path} is not a ULog file (its 16-byte header is missing or cut)")
    start_us = int(data[8:16].view("<u8")[0])
    records, skipped, truncated = scan_ulog(data, HEADER_BYTES)
    stats = ReadStats(skipped_bytes=skipped, truncated=truncated)
    log = ULog(start_us, {}, {}, [], [], [], stats, data=data)
    subscriptions = _read_messages(data, records, log)
    _read_topics(data, records, subscriptions, log)
    log.stats.messages = len(records) - log.stats.bad_records
    return log


@dataclass
class _Subscription:
    name: str
    multi_id: int
    dtype: np.dtype = field(default_factory=lambda: np.dtype("u1"))


def _read_messages(data: np.ndarray, records: np.ndarray, log: ULog) -> dict[int, _Subscription]:
    """Every message but data (few: formats, info, parameters, subscriptions, log
    messages): into ``log``; the subscriptions by msg_id, with their formats."""
    formats: dict[str, str] = {}
    subscriptions: dict[int, _Subscription] = {}
    data_section = False
    stamps = _record_times(data, records)
    log.end_us = int(stamps[-1]) if len(stamps) else 0
    times = stamps[records[:, 2] != ULOG_DATA].astype(np.int64).tolist()
    latest = 0  # µs: the latest time stamp met, data or log message
    for (at, size, kind), data_time in zip(records[records[:, 2] != ULOG_DATA], times, strict=True):
        when = latest = max(latest, data_time)
        payload = data[at + 3 : at + 3 + size].tobytes()
        letter = chr(kind)
        if letter == "F":
            name, _, body = payload.decode("ascii", "replace").partition(":")
            formats[name] = body
        elif letter == "A" and size >= 3:
            data_section = True
            msg_id = int.from_bytes(payload[1:3], "little")
            subscriptions[msg_id] = _Subscription(
                payload[3:].decode("ascii", "replace"), payload[0]
            )
        elif letter in "IP" and size >= 1:
            key, value = _key_value(payload[1 : 1 + payload[0]], payload[1 + payload[0] :])
            if letter == "I":
                log.info[key] = value
            elif data_section:
                log.parameter_changes.append((when, key, float(value)))
            else:
                log.parameters[key] = float(value)
        elif letter in "LC":
            head = 1 + (2 if letter == "C" else 0)
            if size >= head + 8:
                stamp = int.from_bytes(payload[head : head + 8], "little")
                level = payload[0] - ord("0") if payload[0] >= ord("0") else payload[0]
                text = payload[head + 8 :].decode("utf-8", "replace").rstrip("\x00")
                log.messages.append((stamp, min(max(level, 0), 7), text))
                latest = max(latest, stamp)
        elif letter == "O" and size >= 2:
            log.dropouts.append((when, int.from_bytes(payload[:2], "little")))
        elif letter == "B" and size >= 16 and payload[8] & ~INCOMPAT_DATA_APPENDED:
            log.warnings.append("the log sets format flags this reader does not know")
    dtypes: dict[str, np.dtype] = {}
    for msg_id, subscription in list(subscriptions.items()):
        try:
            subscription.dtype = _dtype(subscription.name, formats, dtypes)
        except (KeyError, ValueError, TypeError):
            log.warnings.append(f"topic {subscription.name}: its format is missing or unreadable")
            del subscriptions[msg_id]
    return subscriptions


def _record_times(data: np.ndarray, records: np.ndarray) -> np.ndarray:
    """For each message, the latest data time stamp up to it (µs; 0 before the first):
    when a parameter changed or a dropout happened. A topic's timestamp is its
    first field (PX4 writes it first in every format)."""
    is_data = records[:, 2] == ULOG_DATA
    stamps = np.zeros(len(records), dtype=np.uint64)
    offsets = records[is_data, 0] + 5  # header (3) + msg_id (2)
    if len(offsets):
        stamps[is_data] = gather(data, offsets, 8, 8).view("<u8").ravel()
        stamps = np.maximum.accumulate(stamps)
    return stamps


def _read_topics(
    data: np.ndarray, records: np.ndarray, subscriptions: dict[int, _Subscription], log: ULog
) -> None:
    """Where each subscription's data messages are (read when asked for: a replay
    shows a fifth of a PX4 log's topics)."""
    rows = records[records[:, 2] == ULOG_DATA]
    msg_ids = data[rows[:, 0] + 3].astype(np.int64) | (data[rows[:, 0] + 4].astype(np.int64) << 8)
    order = np.argsort(msg_ids, kind="stable")
    ids, starts = np.unique(msg_ids[order], return_index=True)
    for msg_id, chunk in zip(ids, np.split(order, starts[1:]), strict=True):
        subscription = subscriptions.get(int(msg_id))
        if subscription is None:
            log.stats.bad_records += len(chunk)
            continue
        dtype = subscription.dtype
        sizes = rows[chunk, 1] - 2
        good = (sizes <= dtype.itemsize) & (sizes >= _required_size(dtype))
        log.stats.bad_records += int((~good).sum())
        if good.any():
            offsets = rows[chunk[good], 0] + 5  # header (3) + msg_id (2)
            key = (subscription.name, subscription.multi_id)
            log.located[key] = _Located(offsets, sizes[good], dtype)


def _required_size(dtype: np.dtype) -> int:
    """The bytes a data message must hold: all but a trailing padding field, which PX4
    may leave out."""
    names = dtype.names or ()
    if names and names[-1].startswith("_padding"):
        return int(dtype.fields[names[-1]][1])  # type: ignore[index]
    return dtype.itemsize


def _dtype(name: str, formats: dict[str, str], done: dict[str, np.dtype]) -> np.dtype:
    """The packed numpy dtype of format ``name`` (nested formats recursively)."""
    if name in done:
        return done[name]
    fields: list[tuple[Any, ...]] = []
    for item in formats[name].split(";"):
        if not item.strip():
            continue
        type_name, field_name = item.strip().rsplit(" ", 1)
        match = FIELD.match(type_name.strip())
        if match is None:
            raise ValueError(f"unreadable field type {type_name!r}")
        base, count = match.group(1), match.group(2)
        if base == "char" and count:
            fields.append((field_name, f"S{count}"))
            continue
        element = np.dtype(BASIC[base]) if base in BASIC else _dtype(base, formats, done)
        fields.append((field_name, element, (int(count),)) if count else (field_name, element))
    done[name] = np.dtype(fields)
    return done[name]


def _key_value(key: bytes, value: bytes) -> tuple[str, Any]:
    """An info or parameter message's key (``type name``) and its decoded value."""
    type_name, _, name = key.decode("ascii", "replace").partition(" ")
    match = FIELD.match(type_name)
    base = match.group(1) if match else "char"
    if base == "char":
        return name, value.decode("utf-8", "replace").rstrip("\x00")
    numbers = np.frombuffer(value, dtype=BASIC.get(base, "u1"))
    if match and match.group(2):
        return name, numbers.tolist()
    return name, numbers[0].item() if len(numbers) else None
