"""How to type this installation's commands so that they run in the user's shell.

``make`` installs ``quadsitl``, ``gcs-replay`` and the Rerun viewer ``rerun`` into the
venv's ``bin``, which is on PATH only once the venv is activated. A command printed for
the user to copy (``open it with: rerun FLIGHT.rrd``) is written so that it runs as
typed: the bare name where PATH finds this installation's script, else its path.
"""

from __future__ import annotations

import os
import shlex
import shutil
import sys
from pathlib import Path


def runnable(name: str, module: str) -> str:
    """``name`` if PATH finds this interpreter's console script of that name, else the
    script's path (relative when under the working folder: ``.venv/bin/rerun``), else
    ``PYTHON -m module`` (no script installed)."""
    beside = Path(sys.executable).parent / name
    found = shutil.which(name)
    if beside.is_file() and os.access(beside, os.X_OK):
        if found is not None and Path(found).resolve() == beside.resolve():
            return name
        return shlex.quote(_shortest(beside))
    if found is not None:
        return name
    return f"{shlex.quote(sys.executable)} -m {module}"


def _shortest(path: Path) -> str:
    """``path`` relative to the working folder when inside it, else absolute."""
    absolute = path.absolute()
    try:
        return str(absolute.relative_to(Path.cwd()))
    except ValueError:
        return str(absolute)
