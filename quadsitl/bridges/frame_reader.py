"""MAVLink 2 frames out of a byte stream (TCP), where datagrams do not mark where a frame
ends: PX4's simulator_mavlink connection (:mod:`.px4_tcp`, and its fake,
:mod:`.fake_px4`). Each frame is parsed by :mod:`quadsitl.wire.fast_codec`.
"""

from __future__ import annotations

from quadsitl.wire import fast_codec as FC


class FrameReader:
    """MAVLink 2 frames out of a byte stream (TCP): :meth:`feed` returns the frames
    complete so far and keeps the rest. Bytes that are not a frame with a good CRC are
    skipped (``skipped`` counts them), so a damaged stream resynchronises."""

    LIMIT = 1 << 20  # bytes kept waiting for the rest of a frame

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.skipped = 0

    def feed(self, data: bytes) -> list[FC.Frame]:
        buf = self.buffer
        buf += data
        frames: list[FC.Frame] = []
        i, end = 0, len(buf)
        while True:
            start = buf.find(FC.MAGIC, i)
            if start < 0:
                self.skipped += end - i
                i = end
                break
            self.skipped += start - i
            if start + 3 > end:
                i = start
                break
            signed = FC.SIGNATURE_SIZE if buf[start + 2] & FC.SIGNED else 0
            size = FC.HEADER_SIZE + buf[start + 1] + FC.CRC_SIZE + signed
            if start + size > end:
                i = start
                break
            parsed = next(FC.parse(bytes(buf[start : start + size])), None)
            if parsed is None:  # a 0xFD that starts no frame: look further
                self.skipped += 1
                i = start + 1
                continue
            frames.append(parsed)
            i = start + size
        del buf[:i]
        if len(buf) > self.LIMIT:
            self.skipped += len(buf)
            buf.clear()
        return frames
