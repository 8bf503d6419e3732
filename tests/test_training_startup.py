"""The training commands as a user stops or misdirects them: Ctrl-C twice during start-up
is one line and exit status 130, an output folder that cannot be written one sentence
naming it, before any work, never a traceback or a bare errno line."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from policies.interrupt import INTERRUPTED
from tests.conftest import cli, refused_here

HOVER = Path(__file__).parents[1] / "policies" / "checkpoints" / "hover.pt"


def _wait_for_line(process: subprocess.Popen[str], text: str) -> list[str]:
    """stderr lines up to and including the first that holds ``text``."""
    assert process.stderr is not None
    lines = []
    for line in process.stderr:
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"no line with {text!r}: {''.join(lines)}")


def test_a_second_ctrl_c_while_stopping_ends_at_once_with_one_line():
    """The first Ctrl-C interrupts the start-up; the second lands in its clean-up (an env
    closing, an import unwinding), which would print a KeyboardInterrupt traceback: it
    ends the process at once, with one line and status 130."""
    script = textwrap.dedent(
        """
        import sys, time
        from policies.interrupt import second_interrupt_stops

        with second_interrupt_stops("quadsitl train"):
            try:
                print("starting", file=sys.stderr, flush=True)
                time.sleep(60)  # torch's import, the envs' construction
            finally:
                print("cleaning up", file=sys.stderr, flush=True)
                time.sleep(60)  # an env's close
        """
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        _wait_for_line(process, "starting")
        process.send_signal(signal.SIGINT)
        _wait_for_line(process, "cleaning up")
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == INTERRUPTED, err
    assert err.strip() == "quadsitl train: interrupted again; stopped at once"


def test_ctrl_c_twice_while_training_starts_is_one_line_and_status_130(tmp_path):
    """``quadsitl train`` interrupted twice right after its start-up line (torch
    imported, the envs being made): no traceback, the last line says it was interrupted."""
    process = subprocess.Popen(
        cli("train --task hover --algo ppo --preset fast --quiet --runs", tmp_path),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        before = _wait_for_line(process, "iterations of")
        process.send_signal(signal.SIGINT)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=120)
    finally:
        process.kill()
    err = "".join(before) + err
    assert process.returncode == INTERRUPTED, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert "interrupted" in err.strip().splitlines()[-1]


def _unwritable_folder(tmp_path: Path) -> Path:
    """A folder this process cannot create files in: a read-only one (0o500), or, as
    root (whom permissions do not stop), /proc, which refuses new files to everyone."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        (folder / "probe").touch()
    except OSError:
        return folder
    (folder / "probe").unlink()
    return Path("/proc")


@pytest.mark.parametrize(
    ("command", "what"),
    [
        (["robustness", str(HOVER), "--episodes", "1", "--out"], "the robustness tables"),
        (["plot", "runs-that-are-not-read", "-o"], "the plots"),
        (["export", str(HOVER), "--format", "c", "-o"], "hover.h"),
        (["train", "--task", "hover", "--algo", "ppo", "--runs"], "the run"),
    ],
    ids=["robustness", "plot", "export", "train"],
)
@pytest.mark.parametrize("where", ["read-only", "proc"])
def test_an_output_folder_that_cannot_be_written_is_one_sentence_before_any_work(
    command, what, where, tmp_path, monkeypatch
):
    """``--out /proc/...`` or a read-only folder: one line that names the folder and
    why, status 2, nothing run (``robustness`` used to fly every rung, then print a bare
    errno line)."""
    monkeypatch.chdir(tmp_path)
    base = _unwritable_folder(tmp_path) if where == "read-only" else Path("/proc")
    out = base / "quadsitl-out"
    if command[0] == "export":
        out = out.parent  # an existing folder: export writes hover.h into it
    result = refused_here(*command, str(out))
    assert result.returncode == 2, result.stderr
    assert "robustness ladder" not in result.stdout  # no episode flew
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr and "Errno" not in lines[0]
    assert lines[0].startswith(f"quadsitl {command[0]}: error: cannot write {what} to ")
    assert f"{base} is not writable" in lines[0]
