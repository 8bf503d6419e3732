"""A ``quadsitl sim --lockstep`` child process for one MAVLink environment.

It is started on a free UDP port (or a given one) and dies with its parent: on
``stop()``, on interpreter exit, and, through Linux's parent-death signal, even when the
parent is killed outright. Nothing is left running and the port is released.

That signal follows the *thread* that started the child, not its process, so every
child is started from one long-lived spawner thread: an env made in a worker thread
keeps its simulator when that thread ends.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import os
import queue
import signal
import subprocess
import sys
import threading
import weakref
from concurrent.futures import Future
from typing import Any

from quadsitl.wire.addresses import free_udp_port

PR_SET_PDEATHSIG = 1
UDP_TABLES = ("/proc/net/udp", "/proc/net/udp6")  # Linux's bound UDP sockets


def _die_with_parent() -> None:  # runs in the child between fork and exec
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class _Spawner:
    """Runs ``subprocess.Popen`` on one daemon thread that lives as long as the process."""

    def __init__(self) -> None:
        self._requests: queue.SimpleQueue[tuple[Future[Any], dict[str, Any]]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def popen(self, **kwargs: Any) -> subprocess.Popen[bytes]:
        with self._lock:  # a forked child inherits a dead thread: start a new one
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(
                    target=self._serve, name="quadsitl-sim-spawner", daemon=True
                )
                self._thread.start()
        future: Future[subprocess.Popen[bytes]] = Future()
        self._requests.put((future, kwargs))
        return future.result()

    def _serve(self) -> None:
        while True:
            future, kwargs = self._requests.get()
            try:
                future.set_result(subprocess.Popen(**kwargs))
            except BaseException as error:  # handed to the caller
                future.set_exception(error)


_SPAWNER = _Spawner()


def terminate(process: subprocess.Popen, wait: float = 5.0) -> None:
    """End ``process``: SIGTERM, then SIGKILL if it has not ended within ``wait`` s."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(wait)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


class SimProcess:
    """The simulator as a child process. ``args``: extra ``quadsitl sim`` options;
    ``env``: extra environment variables (e.g. QUADSITL_SIGNING_KEY); ``host``: the
    address its lockstep link listens on (loopback unless the envs are elsewhere)."""

    def __init__(
        self,
        args: list[str],
        port: int | None = None,
        env: dict[str, str] | None = None,
        host: str = "127.0.0.1",
    ) -> None:
        self.host = host
        self.port = port if port is not None else free_udp_port(host)
        self.command = [
            sys.executable,
            "-m",
            "quadsitl.cli",
            "sim",
            "--lockstep",
            "--quiet",
            "--hil",
            f"udpin:{host}:{self.port}",
            "--logs",
            "none",
            *args,
        ]
        self.process = _SPAWNER.popen(
            args=self.command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env={**os.environ, **(env or {})},
            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
        )
        self._finalizer = weakref.finalize(self, terminate, self.process)
        atexit.register(self._finalizer)

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) of its lockstep link."""
        return self.host, self.port

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    @property
    def listening(self) -> bool:
        """Whether its lockstep link is open: the simulator has started (imports, the
        compiled kernels, its vehicles; the link opens last) and answers from now on.
        True where the host cannot tell (not Linux)."""
        bound = udp_port_bound(self.port)
        return True if bound is None else bound

    def exit_message(self) -> str:
        """Why the process ended (its exit code and last error line), once it has."""
        if self.alive:
            return "still running"
        err = self.process.stderr.read().decode(errors="replace") if self.process.stderr else ""
        lines = [line for line in err.strip().splitlines() if not line.startswith("timing:")]
        reason = lines[-1] if lines else "no message"
        return f"exited with code {self.process.returncode}: {reason}"

    def stop(self) -> None:
        self._finalizer()
        if self.process.stderr:
            self.process.stderr.close()


def udp_port_bound(port: int) -> bool | None:
    """Whether a socket on this host has bound UDP ``port`` (read from Linux's socket
    tables, so nothing is bound to find out); None where the tables cannot be read."""
    wanted = f":{port:04X}"
    found = False
    for table in UDP_TABLES:
        try:
            with open(table) as rows:
                next(rows, None)  # the header
                found = found or any(row.split()[1].endswith(wanted) for row in rows)
        except OSError:
            if table == UDP_TABLES[0]:
                return None
    return found
