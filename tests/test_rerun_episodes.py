"""Episodes in Rerun (``render_mode="rerun"``, ``quadsitl eval --rerun``): what is
recorded, however the buffer of steps was cut when it was sent; read back with Rerun's
own reader."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rrc

from quadsitl.viz.episode_writer import wait_for_recordings
from tests.test_rerun import check_panels, rows_per_entity, scalars


def test_render_mode_rerun_records_episodes(tmp_path):
    import gymnasium as gym

    import quadsitl  # noqa: F401

    out = tmp_path / "episodes.rrd"
    env = gym.make("QuadSITL/RandomWaypoint-v0", render_mode="rerun", rerun_save=str(out))
    steps = 0
    for seed in (0, 1):
        env.reset(seed=seed)
        steps += 1
        while True:
            *_, terminated, truncated, _ = env.step(np.zeros(4, np.float32))
            steps += 1
            if terminated or truncated:
                break
    env.close()
    wait_for_recordings()  # close() hands over; the writer process finishes the file
    rows = rows_per_entity(out, static=False)
    assert rows["/world/vehicle"] == rows["/plots/height_above_goal/height"] == steps
    # A waypoint stays put: logged every 10 steps (episodes share the step timeline).
    assert rows["/world/goal"] == rows["/world/trajectory"] < steps / 5
    # No reward at a reset, nor at an episode's last step (its outcome event has it).
    assert rows["/plots/reward/reward"] == steps - 4
    check_panels(
        out,
        {
            "plots/reward",
            "plots/reward_terms",
            "plots/distance_to_goal",
            "plots/height_above_goal",
            "plots/speed",
        },
    )
    assert rows["/events"] == 2  # each episode's outcome
    assert "/plots/wind/speed" not in rows and "/world/wind" not in rows  # still air
    with pytest.raises(ValueError, match="render_mode"):
        gym.make("QuadSITL/Hover-v0", render_mode="ansi")


def test_episodes_in_wind_show_it(tmp_path):
    """An env flying in a 5 m/s west wind records the wind panel (the air's speed, 5 m/s
    on average with turbulence) and an arrow at the vehicle, blowing east."""
    import gymnasium as gym

    import quadsitl  # noqa: F401

    out = tmp_path / "windy.rrd"
    wind = {"speed": 5.0, "from_deg": 270.0, "turbulence": "light"}
    env = gym.make("QuadSITL/Hover-v0", render_mode="rerun", rerun_save=str(out), wind=wind)
    env.reset(seed=0)
    for _ in range(40):
        env.step(np.zeros(4, np.float32))
    env.close()
    wait_for_recordings()
    check_panels(out, {"plots/wind", "plots/height_above_goal"})
    speed = scalars(out, "/plots/wind/speed")
    assert len(speed) == 41 and 3.0 < speed.mean() < 7.0 and speed.std() > 0.01
    arrows = rows_per_entity(out, static=False)["/world/wind"]
    assert arrows == 41


def _record_episodes(path: Path, task: str, seeds: tuple[int, ...]) -> int:
    """Episodes of ``task`` flown on hover actions, recorded to ``path``; the rows."""
    import gymnasium as gym

    import quadsitl  # noqa: F401

    env = gym.make(f"QuadSITL/{task}-v0", render_mode="rerun", rerun_save=str(path))
    steps = 0
    for seed in seeds:
        env.reset(seed=seed)
        steps += 1
        done = False
        while not done:
            *_, terminated, truncated, _ = env.step(np.zeros(4, np.float32))
            steps += 1
            done = terminated or truncated
    env.close()
    wait_for_recordings()
    return steps


def test_episodes_sent_row_by_row_equal_episodes_sent_at_once(tmp_path, monkeypatch):
    """A step only buffers its row; the buffer goes to Rerun when it is full or old. How
    it was cut must not show: a moving target is logged at every step, each episode's
    path ends where the vehicle is at its end, and the series are the same."""
    from quadsitl.viz import episode_view

    whole = tmp_path / "whole.rrd"
    monkeypatch.setattr(episode_view, "FLUSH_AFTER", math.inf)  # sent at close
    steps = _record_episodes(whole, "TargetFollow", (0, 1))
    monkeypatch.setattr(episode_view, "FLUSH_AFTER", -1.0)  # every row sent on its own
    cut = tmp_path / "cut.rrd"
    assert _record_episodes(cut, "TargetFollow", (0, 1)) == steps
    for rrd in (whole, cut):
        rows = rows_per_entity(rrd, static=False)
        assert rows["/world/goal"] == rows["/world/vehicle"] == steps  # the target moves
        assert rows["/events"] == 2
    for entity in ("/plots/distance_to_goal/distance", "/plots/reward/reward"):
        np.testing.assert_array_equal(scalars(whole, entity), scalars(cut, entity))
    events = [_texts(rrd) for rrd in (whole, cut)]  # lengths and returns, however cut
    assert events[0] == events[1] and all("return" in text for text in events[0])
    whole_paths, cut_paths, vehicle = _paths(whole), _paths(cut), _poses(whole)
    assert {e for e, _ in whole_paths} == {e for e, _ in vehicle} == {0, 1}
    assert whole_paths.keys() == cut_paths.keys()  # logged at the same steps
    for (episode, step), path in whole_paths.items():
        assert len(path) > 10
        # Sent at once: each episode's whole path, ending where the vehicle ends.
        end = max(s for e, s in vehicle if e == episode)
        np.testing.assert_allclose(path[-1], vehicle[episode, end], atol=1e-5)
        # Sent row by row: as far as the vehicle had flown then.
        np.testing.assert_allclose(cut_paths[episode, step][-1], vehicle[episode, step], atol=1e-5)


def _per_row(rrd: Path, entity: str, column: str) -> dict[tuple[int, int], list]:
    """(episode, step) -> the first instance of ``column`` logged at ``entity``, which
    has the Arrow type the viewer reads (it shows nothing of a column that has not)."""
    import rerun as rr

    expected = {
        "LineStrips3D:strips": rr.components.LineStrip3DBatch._ARROW_DATATYPE,
        "Transform3D:translation": rr.components.Translation3DBatch._ARROW_DATATYPE,
    }[column]
    found = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            assert batch.schema.field(column).type.value_type == expected, column
            for episode, step, value in zip(
                batch.column("episode").to_pylist(),
                batch.column("step").to_pylist(),
                batch.column(column).to_pylist(),
                strict=True,
            ):
                found[episode, step] = value[0]
    return found


def _texts(rrd: Path) -> list[str]:
    texts = []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path == "/events":
            texts += [t[0] for t in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    return texts


def _paths(rrd: Path) -> dict[tuple[int, int], list]:
    return _per_row(rrd, "/world/trajectory", "LineStrips3D:strips")


def _poses(rrd: Path) -> dict[tuple[int, int], list]:
    return _per_row(rrd, "/world/vehicle", "Transform3D:translation")


def test_an_env_never_closed_still_leaves_its_whole_recording(tmp_path):
    """The rows go to a writer process; when the program ends without closing the env,
    what it buffered is handed over and written before the program exits."""
    import subprocess
    import sys

    out = tmp_path / "unclosed.rrd"
    script = (
        "import gymnasium as gym, numpy as np, quadsitl\n"
        f"env = gym.make('QuadSITL/Hover-v0', render_mode='rerun', rerun_save={str(out)!r})\n"
        "env.reset(seed=0)\n"
        "for _ in range(300): env.step(np.zeros(4, np.float32))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert rows_per_entity(out, static=False)["/world/vehicle"] == 301


def test_a_dead_writer_loses_the_recording_not_the_env(tmp_path):
    import gymnasium as gym

    import quadsitl  # noqa: F401

    env = gym.make("QuadSITL/Hover-v0", render_mode="rerun", rerun_save=str(tmp_path / "x.rrd"))
    env.reset(seed=0)
    view = env.unwrapped.view
    # The kill inside the block: under load the feeder may not have sent the reset's
    # message yet, and its failed write (the warning) can come at once.
    with pytest.warns(RuntimeWarning, match="Rerun recording lost"):
        view.writer.process.kill()
        view.writer.process.wait()
        for _ in range(50):
            env.step(np.zeros(4, np.float32))
        view.flush()
        view.writer.feeder.join(10)
    obs, *_ = env.step(np.zeros(4, np.float32))  # the env flies on
    assert np.isfinite(obs).all()
    buffers = set()
    for _ in range(3):  # and its buffers come back: nothing piles up for a dead writer
        for _ in range(20):
            env.step(np.zeros(4, np.float32))
        view.flush()
        buffers.add(id(view.buffer))
    assert view.writer.outbox.empty() and len(buffers) <= 2
    env.close()


def test_ctrl_c_in_the_terminal_leaves_the_recording_whole(tmp_path):
    """Ctrl-C reaches the env's program and its writer (one process group): the program
    stops, the writer finishes the file with every row handed over."""
    import signal
    import subprocess
    import sys

    out = tmp_path / "interrupted.rrd"
    script = (
        "import gymnasium as gym, numpy as np, quadsitl, sys, time\n"
        f"env = gym.make('QuadSITL/Hover-v0', render_mode='rerun', rerun_save={str(out)!r})\n"
        "env.reset(seed=0)\n"
        "for _ in range(200): env.step(np.zeros(4, np.float32))\n"
        "env.unwrapped.view.flush()\n"
        "try:\n"  # (before the print: a Ctrl-C that follows it at once lands in here)
        "    print('stepped', flush=True)\n"
        "    time.sleep(120)\n"
        "except KeyboardInterrupt:\n"
        "    sys.exit(130)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job
    )
    assert process.stdout is not None
    assert process.stdout.readline().strip() == "stepped"
    os.killpg(process.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in err, err[-2000:]
    assert rows_per_entity(out, static=False)["/world/vehicle"] == 201
