"""Where a Rerun recording goes: a spawned viewer window, an .rrd file, or the web viewer
served from this host; and, where no window can be shown (no display, no viewer
installed), a file instead, said where. What the recording shows is
:mod:`quadsitl.viz.scene`'s: :func:`open_recording` sets it up there.
"""

from __future__ import annotations

import atexit
import itertools
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from quadsitl.console import runnable
from quadsitl.viz.scene import blueprint, setup


def viewer_executable() -> str | None:
    """The Rerun viewer: beside this interpreter (a venv's ``bin``, so it is found without
    activating the venv), else on PATH."""
    beside = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("rerun")


def viewer_binary() -> str | None:
    """The viewer program itself (rerun-sdk's ``rerun_cli/rerun``), not the ``rerun``
    launcher script, so that stopping the process stops the viewer; else the launcher."""
    try:
        import rerun_cli
    except ImportError:
        return viewer_executable()
    binary = Path(rerun_cli.__file__).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    return str(binary) if binary.is_file() else viewer_executable()


def why_no_viewer(executable: str | None) -> str | None:
    """Why no viewer window can be shown here (None: one can), given the viewer found."""
    if executable is None:
        return "the Rerun viewer executable is not installed"
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        return "there is no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    return None


def fallback_path(name: str) -> Path:
    """Where a recording goes when no viewer can be shown."""
    folder = Path(os.environ.get("QUADSITL_RERUN_DIR") or Path(tempfile.gettempdir()) / "quadsitl")
    folder.mkdir(parents=True, exist_ok=True)
    return folder / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{next(_COUNTER)}.rrd"


_COUNTER = itertools.count()


def check_output_path(path: str | Path) -> Path:
    """A clear ValueError for an .rrd path that cannot be written."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"cannot write {path}: folder {folder} does not exist")
    if path.is_dir():
        raise ValueError(f"cannot write {path}: it is a folder")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"cannot write {path}: folder {folder} is not writable")
    return path


def open_recording(
    name: str,
    save: str | Path | None = None,
    spawn: bool = False,
    default_blueprint: rrb.Blueprint | None = None,
    notice: Callable[[str], None] | None = None,
    scale: float = 1.0,
    web: bool = False,
    vehicle: bool = True,
    home: bool = True,
    layout_later: bool = False,
) -> rr.RecordingStream:
    """A recording stream saved to ``save`` (an .rrd path), sent to a spawned viewer, or
    (``web``) served with the web viewer on this host (see :func:`serve_web`).

    Where a viewer cannot be shown (no display, no viewer installed), the recording goes
    to a file instead (under QUADSITL_RERUN_DIR or the temporary folder) and a warning
    says where: rendering never fails because of the machine it runs on. ``notice``
    takes that message (a command line prints it as one plain line); without it, it is
    a RuntimeWarning (library use). ``scale``: how many times life size the vehicle is
    drawn (:func:`model_scale`); ``vehicle``: False for a fleet, which draws its own;
    ``home``: False for a task's episodes (their origin is the task's, not a home);
    ``layout_later``: no layout now, the caller sends it once the data is known (one
    recording, one layout: :func:`send_layout`).
    """
    rec = rr.RecordingStream(name)
    layout: rrb.Blueprint | None = blueprint() if default_blueprint is None else default_blueprint
    if layout_later:
        layout = None
    if web:
        serve_web(rec, layout)
    elif spawn and save is None:
        executable = viewer_executable()
        reason = why_no_viewer(executable)
        if reason is None and executable is not None:
            rr.spawn(executable_path=executable, default_blueprint=layout, recording=rec)
        else:
            save = fallback_path(name)
            message = (
                f"no Rerun viewer can be shown: {reason}; recording to {save} "
                f"(open it with: {runnable('rerun', 'rerun')} {save})"
            )
            if notice is not None:
                notice(message)
            else:
                warnings.warn(message, RuntimeWarning, stacklevel=2)
    if save is not None:
        rec.save(check_output_path(save), default_blueprint=layout)
    if layout is not None:
        send_layout(rec, layout)
    setup(rec, scale, vehicle, home)
    return rec


def send_layout(rec: rr.RecordingStream, layout: rrb.Blueprint) -> None:
    """The active layout too: a viewer that showed another recording of the same kind
    (same application id) would otherwise keep that one's panels."""
    rec.send_blueprint(layout, make_active=True, make_default=True)


def serve_web(rec: rr.RecordingStream, layout: rrb.Blueprint | None) -> str:
    """Serve ``rec`` and the web viewer on this host; prints and returns the page's URL.

    The Rerun viewer executable runs as a child process with ``--serve-web``, bound to
    QUADSITL_WEB_BIND (default 127.0.0.1: loopback, as the rest of quadsitl), its page on
    QUADSITL_WEB_PORT (default 9090) and the data (gRPC) on QUADSITL_GRPC_PORT (default
    9876); the recording is streamed to it and it ends with this process.
    """
    executable = viewer_binary()
    if executable is None:
        raise ValueError("the web viewer needs the Rerun viewer executable (rerun-sdk)")
    bind = os.environ.get("QUADSITL_WEB_BIND") or "127.0.0.1"
    grpc_port = int(os.environ.get("QUADSITL_GRPC_PORT") or 9876)
    web_port = int(os.environ.get("QUADSITL_WEB_PORT") or 9090)
    for port in (grpc_port, web_port):
        with socket.socket() as probe:
            try:
                probe.bind((bind, port))
            except OSError as error:
                raise ValueError(
                    f"the Rerun web viewer cannot listen on {bind}:{port}: {error.strerror} "
                    "(set QUADSITL_WEB_PORT / QUADSITL_GRPC_PORT)"
                ) from None
    server = subprocess.Popen(
        [
            *(executable, "--serve-web", "--bind", bind, "--port", str(grpc_port)),
            *("--web-viewer-port", str(web_port), "--hide-welcome-screen"),
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
    )
    atexit.register(_stop, server)
    host = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
    grpc_url = f"rerun+http://{host}:{grpc_port}/proxy"
    _wait_for_port(host, grpc_port, server)
    rec.connect_grpc(grpc_url, default_blueprint=layout)
    url = f"http://{host}:{web_port}/?url={grpc_url}"
    print(f"Rerun web viewer: open {url}", flush=True)
    return url


def _wait_for_port(host: str, port: int, server: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise ValueError(f"the Rerun web viewer could not start (is port {port} in use?)")
        try:
            socket.create_connection((host, port), timeout=0.5).close()
            return
        except OSError:
            time.sleep(0.1)
    raise ValueError(f"the Rerun web viewer did not open port {port} within {timeout:.0f} s")


def _die_with_parent() -> None:
    """In the child: SIGTERM when the process that started it dies, however it dies
    (Linux prctl PR_SET_PDEATHSIG), so no server outlives the simulator."""
    import ctypes
    import signal

    ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG


def _stop(server: subprocess.Popen) -> None:
    if server.poll() is None:
        server.terminate()
        try:
            server.wait(timeout=5)
        except subprocess.TimeoutExpired:
            server.kill()
