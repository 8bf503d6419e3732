"""A UDP relay that loses and delays datagrams: to try a link's worst days on loopback.

Listens on ``listen`` (HOST:PORT); the first peer that sends to it is the client, whose
datagrams go on to ``target`` and whose answers come back, each dropped with
probability ``drop`` and held back ``delay`` seconds (each way). The lockstep benchmark
and the loss tests put it between a training env and its simulator::

    python -m gcs_tools.relay 127.0.0.1:15000 127.0.0.1:14560 --drop 0.1
"""

from __future__ import annotations

import argparse
import heapq
import random
import select
import socket
import threading
import time


class LossyRelay:
    """Runs in a daemon thread from construction until :meth:`close`.

    Attributes:
        port: where the client sends (the listening port).
        forwarded, dropped: datagram counts, both directions together.
    """

    def __init__(
        self,
        target: tuple[str, int],
        drop: float = 0.0,
        delay: float = 0.0,
        listen: tuple[str, int] = ("127.0.0.1", 0),
        seed: int = 0,
    ) -> None:
        if not 0.0 <= drop < 1.0:
            raise ValueError(f"drop must be a probability in [0, 1), got {drop}")
        if not 0.0 <= delay <= 10.0:
            raise ValueError(f"delay must be in [0, 10] s, got {delay}")
        self.target, self.drop, self.delay = target, drop, delay
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(listen)
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind((listen[0], 0))
        self.port = int(self.front.getsockname()[1])
        self.client: tuple[str, int] | None = None
        self.forwarded = self.dropped = 0
        self._random = random.Random(seed)
        self._queue: list[tuple[float, int, socket.socket, bytes, tuple[str, int]]] = []
        self._count = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-relay", daemon=True)
        self._thread.start()

    def _pass(self, out: socket.socket, data: bytes, to: tuple[str, int]) -> None:
        if self._random.random() < self.drop:
            self.dropped += 1
            return
        self.forwarded += 1
        if self.delay <= 0:
            out.sendto(data, to)
            return
        self._count += 1
        heapq.heappush(self._queue, (time.monotonic() + self.delay, self._count, out, data, to))

    def _run(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            while self._queue and self._queue[0][0] <= now:
                _, _, out, data, to = heapq.heappop(self._queue)
                out.sendto(data, to)
            wait = min(0.05, self._queue[0][0] - now) if self._queue else 0.05
            try:
                readable, _, _ = select.select([self.front, self.back], [], [], max(0.0, wait))
            except (OSError, ValueError):  # closed under us
                return
            for sock in readable:
                try:
                    data, sender = sock.recvfrom(65535)
                except OSError:
                    continue
                if sock is self.front:
                    self.client = sender
                    self._pass(self.back, data, self.target)
                elif self.client is not None:
                    self._pass(self.front, data, self.client)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.front.close()
        self.back.close()

    def __enter__(self) -> LossyRelay:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def _address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host or "127.0.0.1", int(port)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m gcs_tools.relay", description=__doc__)
    parser.add_argument("listen", help="HOST:PORT the client sends to")
    parser.add_argument("target", help="HOST:PORT of the simulator's link")
    parser.add_argument("--drop", type=float, default=0.1, help="loss probability (0.1)")
    parser.add_argument("--delay", type=float, default=0.0, help="one-way delay, s (0)")
    args = parser.parse_args(argv)
    relay = LossyRelay(_address(args.target), args.drop, args.delay, _address(args.listen))
    print(f"relaying {args.listen} -> {args.target}, drop {args.drop}, delay {args.delay} s")
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        relay.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
