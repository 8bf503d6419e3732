"""One time series of a replay, gathered before it is sent: sample by sample (a .tlog,
message by message) or a block at a time (a ULog's or DataFlash log's columns, kept as
the arrays they are: turning a million samples into Python numbers and back cost a
converter more than reading the log)."""

from __future__ import annotations

from typing import Any

import numpy as np


class Series:
    """Time stamps (µs), values (numbers, or rows of a vector) and text levels."""

    def __init__(self) -> None:
        self._times: list[int] = []
        self._values: list[Any] = []
        self._levels: list[str] = []
        self._blocks: list[tuple[np.ndarray, np.ndarray, str | list[str]]] = []
        self._merged: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, stamp_us: int, value: Any, level: str) -> None:
        self._times.append(stamp_us)
        self._values.append(value)
        self._levels.append(level)
        self._merged = None

    def extend(self, stamps_us: np.ndarray, values: Any, levels: str | list[str]) -> None:
        self._blocks.append((np.asarray(stamps_us, dtype=np.int64), np.asarray(values), levels))
        self._merged = None

    def __len__(self) -> int:
        return len(self._times) + sum(len(times) for times, _, _ in self._blocks)

    def _parts(self) -> list[tuple[np.ndarray, np.ndarray, str | list[str]]]:
        parts = list(self._blocks)
        if self._times:
            times = np.asarray(self._times, np.int64)
            parts.append((times, _stack(self._values), self._levels))
        return parts

    @staticmethod
    def _order(times: np.ndarray, parts: int) -> np.ndarray | None:
        """The permutation into time order where blocks and samples mix (None: in order)."""
        if parts > 1 and np.any(np.diff(times) < 0):
            return np.argsort(times, kind="stable")
        return None

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(times int64, values), in time order."""
        if self._merged is None:
            parts = self._parts()
            times = np.concatenate([t for t, _, _ in parts])
            values = np.concatenate([v for _, v, _ in parts]) if len(parts) > 1 else parts[0][1]
            order = self._order(times, len(parts))
            if order is not None:
                times, values = times[order], values[order]
            self._merged = (times, values)
        return self._merged

    def levels(self) -> list[str]:
        """Each sample's level (a text log's), in the order of :meth:`arrays`."""
        parts = self._parts()
        levels = [
            level
            for times, _, block in parts
            for level in ([block] * len(times) if isinstance(block, str) else block)
        ]
        order = self._order(np.concatenate([t for t, _, _ in parts]), len(parts))
        return levels if order is None else [levels[i] for i in order]

    def shift(self, microseconds: int) -> None:
        """Every time stamp moved by ``microseconds`` (flights compared side by side)."""
        self._times = [t + microseconds for t in self._times]
        self._blocks = [(t + microseconds, v, level) for t, v, level in self._blocks]
        self._merged = None

    def replace_values(self, values: np.ndarray) -> None:
        """New values for the same time stamps (in :meth:`arrays`' order), all at the
        first sample's level (rotor speeds, which this is for, have one)."""
        times, _ = self.arrays()
        level = self.levels()[0] if len(times) else "INFO"
        self._times, self._values, self._levels = [], [], []
        self._blocks = [(times, np.asarray(values), level)]
        self._merged = None


def _stack(values: list[Any]) -> np.ndarray:
    """Samples as one array: numbers, or rows of vectors; text stays objects."""
    if values and isinstance(values[0], str):
        return np.asarray(values, dtype=object)
    return np.asarray(values)
