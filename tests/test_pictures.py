"""What the pictures show (``make images``, ``quadsitl eval --rerun``, replays, the PNG
figures), where a test can see it: one palette with distinct colours per plot, plots
fitted to their data (labelled y ends, legends off the data), episode views in the
task's terms, success bands within [0, 1], 3-D tracks at equal scale, and no viewer
notice over a screenshot."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rrc

from quadsitl.viz import palette
from quadsitl.viz.plot_fit import covered, fit, legend_size, nice_range
from quadsitl.viz.scene import series_style
from quadsitl.viz.series_colors import MODE_COLORS, SERIES_NAMES

ROOT = Path(__file__).resolve().parents[1]


def style_color(entity: str) -> int:
    """The colour (packed RGBA) :func:`series_style` gives the series at ``entity``."""
    style = series_style(entity)
    assert style is not None, f"{entity} has no style: Rerun would pick its colour"
    batch = next(
        b for b in style.as_component_batches() if "color" in str(b.component_descriptor())
    )
    return int(batch.as_arrow_array().to_pylist()[0])


def test_the_series_of_a_panel_never_share_a_colour():
    """Each panel's series take the palette's colours in order (east and north, roll,
    pitch and yaw, rotors 1 to 4 ... all different), a setpoint its series' lighter."""
    for panel, names in SERIES_NAMES.items():
        colours = [style_color(f"plots/{panel}/{name}") for name in names]
        assert len(set(colours)) == len(colours), panel
    assert style_color("plots/velocity/east") != style_color("plots/velocity/north")
    assert style_color("plots/rotors/rotor_2") != style_color("plots/rotors/rotor_3")
    assert style_color("plots/attitude/pitch") != style_color("plots/attitude/roll")
    assert style_color("plots/rates/pitch") != style_color("plots/rates/roll")
    setpoints = [style_color(f"plots/attitude/{a}_setpoint") for a in ("roll", "pitch", "yaw")]
    assert len(set(setpoints)) == 3
    assert not set(setpoints) & {style_color(f"plots/attitude/{a}") for a in ("roll", "pitch")}


def test_the_modes_of_a_flight_have_their_own_band_colours():
    flight = ("MANUAL", "POSCTL", "TAKEOFF", "LOITER", "MISSION", "RTL", "LAND")
    assert len({MODE_COLORS[mode] for mode in flight}) == len(flight)
    assert palette.RED not in MODE_COLORS.values()  # red: armed


def test_a_range_is_widened_to_labelled_ends():
    """Rerun labels y at powers of ten only: -8..8 m/s in 80 px showed just "0"; the
    fitted range has its ends on labels (±10), a finer step where the height allows."""
    low, high = nice_range(-8.0, 8.0, 80.0)
    assert low < -10.0 < -8.0 and 8.0 < 10.0 < high < 12.0
    low, high = nice_range(0.2, 4.6, 200.0)  # room for a label a metre
    assert -0.5 < low < 0.0 and 5.0 < high < 5.5
    low, high = nice_range(16.76, 16.80, 130.0)
    assert 16.75 < low < 16.76 and 16.80 < high < 16.81


def test_the_legend_goes_where_it_hides_no_data():
    """A curve falling from the top left to the bottom right: the legend at the top
    right; a band of data across the whole height: room made above or after it."""
    t = np.linspace(0.0, 10.0, 200)
    falling = fit([(t, np.exp(-t))], ["distance"], (350.0, 190.0))
    assert falling is not None and falling.corner == "RightTop"
    noisy = np.sin(7 * t) * 0.9
    crowded = fit([(t, noisy), (t, -noisy)], ["east", "north"], (350.0, 190.0))
    assert crowded is not None
    low, high = crowded.y_range
    box = legend_size(["east", "north"], 350.0, 190.0)
    end = crowded.time_end or 10.0  # room above the data, or after it
    points = np.column_stack([np.r_[t, t] / end, (np.r_[noisy, -noisy] - low) / (high - low)])
    assert covered(crowded.corner, box, points) == 0


def test_a_legend_too_tall_to_sit_above_the_data_sits_after_it():
    """Four noisy wind series filling a short panel (the legend taller than the room
    above any data could be): the time axis runs on past the data's end and the legend
    stands there, hiding nothing."""
    t = np.linspace(0.0, 30.0, 300)
    rng = np.random.default_rng(1)
    series = [(t, rng.uniform(-8, 8, t.size)) for _ in range(4)]
    names = ["east", "north", "up", "speed"]
    size = (330.0, 130.0)
    fitted = fit(series, names, size)
    assert fitted is not None and fitted.time_end is not None and fitted.time_end > 30.0
    low, high = fitted.y_range
    box = legend_size(names, *size)
    times = np.concatenate([s[0] for s in series]) / fitted.time_end
    values = (np.concatenate([s[1] for s in series]) - low) / (high - low)
    assert covered(fitted.corner, box, np.column_stack([times, values])) == 0
    assert fitted.time_end < 30.0 / 0.6  # the data keeps most of the width


def test_a_replay_fits_each_plot_to_its_data(tmp_path):
    """Every time-series panel of a replayed log has a y range and its legend's
    corner; the state band names its modes and colours in its title."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.replay import synthesise
    from gcs_tools.replay import convert

    log = tmp_path / "px4.tlog"
    synthesise(log, seconds=20)
    out = tmp_path / "px4.rrd"
    convert(log, out)
    views = blueprint_views(out)
    series = {name: props for name, props in views.items() if props["kind"] == "TimeSeries"}
    state = next(name for name in series if name.startswith("mode"))
    assert "POSCTL blue" in state and "red" in state
    for name, props in series.items():
        assert "ScalarAxis:range" in props, name
        if name != state:
            assert "PlotLegend:corner" in props, name
            low, high = props["ScalarAxis:range"]
            assert low < high, name


def blueprint_views(rrd: Path) -> dict[str, dict]:
    """The views of the recording's last blueprint: name -> kind and properties."""
    reader = rrc.RrdReader(rrd)
    store = reader.store(store=reader.blueprints()[-1])
    names, props = {}, {}
    for chunk in store.stream():
        batch = chunk.to_record_batch()
        path = chunk.entity_path
        for column in batch.schema.names:
            values = batch.column(column).to_pylist()
            if column == "ViewBlueprint:display_name":
                names[path] = (values[-1][0], None)
            elif column == "ViewBlueprint:class_identifier":
                props.setdefault(path, {})["kind"] = values[-1][0]
            elif column in ("ScalarAxis:range", "PlotLegend:corner"):
                owner = path.rsplit("/", 1)[0]
                props.setdefault(owner, {})[column] = values[-1][0]
    return {names[p][0]: props.get(p, {}) for p in names}


def _record(task: str, path: Path, steps: int | None = None, falling: bool = False) -> None:
    """An episode of ``task`` (v0) on hover actions (zero), or with the rotors at their
    least (``falling``), recorded to ``path``."""
    import gymnasium as gym

    import quadsitl  # noqa: F401
    from quadsitl.viz.episode_writer import wait_for_recordings

    env = gym.make(f"QuadSITL/{task}-v0", render_mode="rerun", rerun_save=str(path))
    env.reset(seed=0)
    action = env.action_space.low if falling else np.zeros(4, np.float32)
    for _ in range(steps or 10_000):
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()
    wait_for_recordings()


def _series(rrd: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(seconds on the ``time`` timeline, values) of a time series of an episode."""
    times, values = [], []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times += [t.total_seconds() for t in batch.column("time").to_pylist()]
        values += [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
    order = np.argsort(times)
    return np.asarray(times)[order], np.asarray(values)[order]


def _texts(rrd: Path) -> list[str]:
    texts = []
    for chunk in rrc.RrdReader(rrd).store().stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/events" and "TextLog:text" in batch.schema.names:
            texts += [t[0] for t in batch.column("TextLog:text").to_pylist()]
    return texts


def test_an_episode_plots_height_above_the_goal_and_keeps_the_end_bonus_apart(tmp_path):
    """Landing with the rotors at their least falls towards the pad, a crash as soon as
    it sinks faster than 2 m/s: that last step's -500 is in the outcome event, not in
    the reward plot; the height is above the pad, on a time axis in simulated seconds."""
    out = tmp_path / "land.rrd"
    _record("Land", out, falling=True)
    seconds, reward = _series(out, "/plots/reward/reward")
    assert np.all(np.abs(reward) < 100.0), reward.min()
    assert np.all(np.diff(seconds) > 0) and seconds[-1] < 10.0  # 20 Hz steps, in s
    _, height = _series(out, "/plots/height_above_goal/height")
    assert 2.0 < height[0] < 4.0 and height[-1] < height[0] - 0.2  # falling towards the pad
    (text,) = _texts(out)
    last = float(text.rsplit("last step ", 1)[1].rstrip(")"))
    assert abs(last) >= 400.0, text  # the landing bonus or the crash penalty
    views = blueprint_views(out)
    assert "height above the goal (m)" in views and "altitude (m)" not in views
    assert views["goal errors of the reward"]["kind"] == "TimeSeries"


def test_a_moving_target_leaves_a_track_and_a_goal_a_pin(tmp_path):
    target = tmp_path / "target.rrd"
    _record("TargetFollow", target, steps=40)
    hover = tmp_path / "hover.rrd"
    _record("Hover", hover, steps=20)
    entities = {c.entity_path for c in rrc.RrdReader(target).store().stream()}
    assert "/world/target_track" in entities
    entities = {c.entity_path for c in rrc.RrdReader(hover).store().stream()}
    assert "/world/goal_pin" in entities and "/world/trajectory" in entities


def test_success_bands_stay_within_zero_and_one():
    """Three seeds at 0, 1 and 1: mean 2/3 ± 0.47 would reach 1.14; the band stops
    at 1 (and a success rate's at 0 below)."""
    import matplotlib.collections

    from policies.plots import curves_figure

    steps = np.array([0.0, 1.0, 2.0])
    success = {"ppo": [(steps, np.array([0.0, 0.0, v])) for v in (0.0, 1.0, 1.0)]}
    returns = {"ppo": [(steps, np.array([1.0, 2.0, 3.0]))] * 3}
    fig = curves_figure("hover", "fast", returns, success)
    bands = [
        c for c in fig.axes[1].collections if isinstance(c, matplotlib.collections.PolyCollection)
    ]
    assert bands
    for band in bands:
        y = np.concatenate([path.vertices[:, 1] for path in band.get_paths()])
        assert y.min() >= 0.0 and y.max() <= 1.0


def test_trajectories_are_drawn_at_equal_scale_and_a_target_per_panel():
    from policies.plots import trajectory_figure

    # A 1.5 m flight east that wobbles 2 cm: the 3-D axes span the same on every axis.
    t = np.linspace(0.0, 1.0, 60)
    track = np.column_stack([1.5 * t, 0.02 * np.sin(20 * t), 0.02 * np.cos(20 * t)])
    fig = trajectory_figure("static_waypoint", [track], [np.tile([1.5, 0.0, 0.0], (60, 1))])
    scene = next(ax for ax in fig.axes if hasattr(ax, "get_zlim"))
    spans = [np.ptp(limits) for limits in (scene.get_xlim(), scene.get_ylim(), scene.get_zlim())]
    assert np.allclose(spans, spans[0]) and spans[0] >= 1.5
    # A moving target: its track drawn, at most three episodes, one panel each.
    tracks = [track + k for k in range(8)]
    fig = trajectory_figure("target_follow", tracks, [tr + 0.5 for tr in tracks])
    scenes = [ax for ax in fig.axes if hasattr(ax, "get_zlim")]
    assert len(scenes) == 3 and all(len(ax.get_lines()) == 2 for ax in scenes)


def test_a_toast_is_seen_in_a_picture():
    from PIL import Image, ImageDraw

    sys.path.insert(0, str(ROOT))
    from benchmarks.headless_viewer import TOAST, TOAST_ROWS, toast_rows

    picture = Image.new("RGB", (1600, 900), (13, 13, 13))
    assert toast_rows(picture) == 0
    ImageDraw.Draw(picture).rectangle((1264, 289, 1592, 325), fill=TOAST)  # one line
    assert toast_rows(picture) >= TOAST_ROWS


def test_the_headless_viewer_shows_no_start_up_notice():
    """The viewer's start-up messages ("Headless viewer running at 1600×900." ...)
    are toasts over the picture's top right for four seconds of frames: a viewer is
    ready only once they are gone."""
    from PIL import Image

    sys.path.insert(0, str(ROOT))
    from benchmarks.headless_viewer import TOAST_ROWS, HeadlessViewer, toast_rows

    try:
        viewer = HeadlessViewer()
        try:
            picture = Image.open(io.BytesIO(viewer.take_screenshot()))
        finally:
            viewer.close()
    except SystemExit as error:  # no Vulkan driver here
        pytest.skip(str(error))
    assert toast_rows(picture) < TOAST_ROWS
