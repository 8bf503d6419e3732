"""Output folders of the training commands, checked before any work: a folder that
cannot be written (read-only, ``/proc``, a file in the way) is one sentence naming it and
why, not an errno line after the work is done."""

from __future__ import annotations

import tempfile
from pathlib import Path


def check_writable(target: Path, what: str = "the run") -> None:
    """A ValueError now if ``what`` cannot be written into the folder ``target`` (made
    later if missing): the folder, or the nearest existing folder above it, is probed
    with a temporary file."""
    folder = Path(target)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise ValueError(f"cannot write {what} to {target}: {folder} is not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise ValueError(
            f"cannot write {what} to {target}: {folder} is not writable ({error.strerror or error})"
        ) from None


def os_error_sentence(error: OSError) -> str:
    """A failed file operation as one sentence: what, where and why."""
    where = f" {error.filename}" if error.filename else ""
    return f"cannot use{where}: {error.strerror or error}"
