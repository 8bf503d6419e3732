"""A column of equal-length 1-D tensors (a bar chart a row: the spectra of a replay) for
Rerun's ``send_columns``, built as one Arrow array.

Rerun's Python side converts a tensor at a time, about half a millisecond each: the
few hundred spectra of an hour's log cost a good part of its replay. Here the rows of a
2-D array become Rerun's TensorData struct (shape, no dimension names, the values in
the buffer union's member of their type) in a few numpy-sized steps. The Arrow type is
Rerun's own, taken from its converter, so that a new Rerun's type is followed
(``tests/test_flight_stack_logs.py`` reads the spectra back).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.components import TensorDataBatch

MEMBERS = {np.dtype(np.float32): "F32", np.dtype(np.float64): "F64"}


@functools.cache
def tensor_type() -> pa.DataType:
    """Rerun's TensorData Arrow type."""
    return TensorDataBatch([np.zeros(1, np.float32)]).as_arrow_array().type


class TensorRows:
    """Each row of ``rows`` (n, width; float32 or float64) a 1-D tensor."""

    def __init__(self, rows: np.ndarray) -> None:
        rows = np.ascontiguousarray(rows)
        if rows.ndim != 2 or rows.dtype not in MEMBERS:
            raise ValueError(f"need a 2-D float32 or float64 array, got {rows.dtype} {rows.shape}")
        self.rows = rows

    def as_arrow_array(self) -> pa.Array:
        count, width = self.rows.shape
        kind = tensor_type()
        shape = pa.ListArray.from_arrays(
            pa.array(np.arange(count + 1, dtype=np.int32)),
            pa.array(np.full(count, width, np.uint64)),
            type=kind.field("shape").type,
        )
        names = pa.nulls(count, type=kind.field("names").type)
        union = kind.field("buffer").type
        member = MEMBERS[self.rows.dtype]
        children = []
        for index in range(union.num_fields):
            field = union.field(index)
            if field.name == member:
                offsets = np.arange(0, count * width + 1, width, dtype=np.int32)
                values = pa.array(self.rows.ravel())
                children.append(
                    pa.ListArray.from_arrays(pa.array(offsets), values, type=field.type)
                )
            else:
                children.append(pa.array([], type=field.type))
        code = union.type_codes[
            [union.field(i).name for i in range(union.num_fields)].index(member)
        ]
        type_ids = pa.py_buffer(np.full(count, code, np.int8))
        offsets = pa.py_buffer(np.arange(count, dtype=np.int32))
        buffer = pa.UnionArray.from_buffers(
            union, count, [None, type_ids, offsets], children=children
        )
        return pa.StructArray.from_arrays([shape, names, buffer], fields=list(kind))


def bar_chart_columns(
    densities: np.ndarray, frequencies: np.ndarray, color: list[int]
) -> list[Any]:
    """The columns of bar charts, a row each: values and abscissa (n, width), all in
    ``color``."""
    colors = rr.components.ColorBatch([color] * len(densities))
    return [
        rr.ComponentColumn(rr.BarChart.descriptor_values(), TensorRows(densities)),
        rr.ComponentColumn(rr.BarChart.descriptor_abscissa(), TensorRows(frequencies)),
        rr.ComponentColumn(rr.BarChart.descriptor_color(), colors),
    ]
