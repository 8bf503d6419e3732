"""STATUSTEXT's chunks (MAVLink 2): a text longer than one message's STATUSTEXT_CHUNK
bytes goes in chunks sharing an ``id`` (1..65535; 0: a text of one message), numbered
by ``chunk_seq`` from 0; the last chunk is shorter than STATUSTEXT_CHUNK bytes, an
empty one if need be (QGroundControl waits for it, src/MAVLink/StatusTextHandler.cc).
"""

from __future__ import annotations

from quadsitl.wire.lockstep import STATUSTEXT_CHUNK


def split_text(text: str) -> list[bytes]:
    """The chunks ``text`` is sent in (one for a short text, empty or not)."""
    data = text.encode("utf-8", "replace")
    chunks = [data[i : i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
    if len(chunks) > 1 and len(chunks[-1]) == STATUSTEXT_CHUNK:
        chunks.append(b"")
    return chunks or [b""]


class TextJoiner:
    """Puts a long text back together from its chunks, as they come in order."""

    def __init__(self) -> None:
        self._chunks: tuple[int, bytes] = (0, b"")  # the text being put together: id, bytes

    def take(self, chunk: bytes, text_id: int, seq: int) -> str | None:
        """The whole text once ``chunk`` completes it, else None."""
        data = chunk.rstrip(b"\0")
        if text_id == 0:
            return data.decode("utf-8", "replace")
        if seq == 0 or self._chunks[0] != text_id:
            self._chunks = (text_id, b"")
        self._chunks = (text_id, self._chunks[1] + data)
        if len(data) < STATUSTEXT_CHUNK:  # the last chunk
            text = self._chunks[1].decode("utf-8", "replace")
            self._chunks = (0, b"")
            return text
        return None
