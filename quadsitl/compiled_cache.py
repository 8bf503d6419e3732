"""Keep numba's on-disk cache of the compiled physics and tasks honest.

numba keys a cached function on its own source file only (its time stamp and size).
A compiled function here calls, inlines or reads constants from functions of other
files (the kernel inlines :mod:`quadsitl.physics.kernel_dynamics` and
:mod:`quadsitl.physics.wind_kernel`, the engine's step calls each task's ``evaluate``),
so an edit to one of those would leave the old machine code in use, silently, until
the caller's own file changed. numba's documentation states the limitation ("changes in
functions defined in a different file" are not detected).

So, before anything is compiled, :func:`drop_stale` hashes every source that compiled
code is built from (:data:`COMPILED_SOURCES`) and, when the hash differs from the one
stamped beside the cache, deletes the package's cached machine code: the next call
compiles afresh (once, about 30 s) and the stamp is renewed. An installed package never
changes, so this costs a user one hash of about 30 files per process (~1 ms).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
from collections.abc import Iterator
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
# Where compiled code and everything it imports live (tests/test_kernel_cache.py checks
# that this covers every module the compiled functions import, directly or not).
COMPILED_SOURCES = (
    "physics",
    "tasks",
    "flight_software/cascade.py",
    "frames.py",
    "registration.py",
    "wire/frame_kernel.py",
)
STAMP = "compiled_sources.sha256"


def source_files() -> list[Path]:
    """The .py files of :data:`COMPILED_SOURCES`, in a fixed order."""
    files: list[Path] = []
    for entry in COMPILED_SOURCES:
        path = PACKAGE / entry
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return files


def sources_digest() -> str:
    digest = hashlib.sha256()
    for path in source_files():
        digest.update(str(path.relative_to(PACKAGE)).encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def cache_files() -> Iterator[Path]:
    """numba's index (.nbi) and machine code (.nbc) files of this package: in the
    ``__pycache__`` folders beside the sources, or under NUMBA_CACHE_DIR if it is set."""
    yield from PACKAGE.rglob("__pycache__/*.nb[ic]")
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root and Path(root).is_dir():
        yield from (p for p in Path(root).rglob("*.nb[ic]") if "quadsitl" in p.parts)


def drop_stale() -> bool:
    """Delete the cached machine code if a compiled source changed since it was stamped;
    True if it did. Safe when several processes start at once (a lock serialises them)
    and where the package cannot be written (an installed copy: nothing to do)."""
    stamp = PACKAGE / "__pycache__" / STAMP
    try:
        stamp.parent.mkdir(exist_ok=True)
        with open(stamp.parent / f"{STAMP}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            digest = sources_digest()
            if stamp.is_file() and stamp.read_text().strip() == digest:
                return False
            for path in cache_files():
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
            stamp.write_text(digest + "\n")
            return True
    except OSError:  # a read-only install: its sources cannot change under its cache
        return False
