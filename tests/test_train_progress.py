"""The training progress line: redrawn in place on a terminal, plain lines at a modest
rate when stderr is a file or a pipe (a log gets no carriage returns)."""

from __future__ import annotations

import io
import sys
import time

import torch

from policies.config import make_config
from policies.train import PLAIN_PROGRESS_EVERY, train


def _short(tmp_path):
    torch.set_num_threads(1)
    config = make_config(
        "hover", "ppo", "fast", total_steps=16_384, num_envs=64, steps_per_env=64, eval_every=0
    )
    return config, tmp_path / "run"


def test_a_log_file_gets_plain_lines_not_carriage_returns(tmp_path, capsys):
    config, run = _short(tmp_path)
    started = time.monotonic()
    train(config, run, progress=True)
    elapsed = time.monotonic() - started
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if "steps/s" in line]
    assert lines and lines[-1].startswith("hover/ppo [" + "#" * 24 + "]")  # the last iteration
    assert len(lines) <= 2 + elapsed / PLAIN_PROGRESS_EVERY  # the first, the last, few between
    assert err.endswith("\n") and "\n\n" not in err


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_one_line_redrawn(tmp_path, monkeypatch):
    config, run = _short(tmp_path)
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    train(config, run, progress=True)
    text = terminal.getvalue()
    assert text.startswith("\rhover/ppo [") and text.endswith("\n") and text.count("\n") == 1
