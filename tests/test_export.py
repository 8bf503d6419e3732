"""quadsitl export: the ONNX file and the C header compute the checkpoint's policy (to
1e-5 on 10,000 observations of real episodes), say what they compute (the contract,
checked against the code), fly in ``quadsitl eval`` and ``quadsitl sim --autopilot``,
and refuse bad input with one line, writing nothing."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.config import make_config
from policies.export.contract import contract_path
from policies.export.parity import max_differences, record_observations
from policies.export.runtimes import CPolicy, load_policy
from policies.export.writer import export
from policies.networks import ActorCritic
from quadsitl.cli import main
from quadsitl.frames import quat_from_euler
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, TaskEngine, TaskOptions
from quadsitl.tasks import features as F
from tests.conftest import run_cli, sim_with_client

CHECKPOINTS = Path(__file__).resolve().parents[1] / "policies" / "checkpoints"
PARITY = 1e-5  # max abs difference of the actions, any two forms
RECORDED = 10_000  # observations compared


def assert_three_forms_agree(source: Path, folder: Path) -> None:
    net, config, _ = checkpoint.load(source)
    onnx_file = export(source, "onnx", folder)[0]
    header = export(source, "c", folder)[0]
    obs = record_observations(net, config, RECORDED)
    assert obs.shape == (RECORDED, net.obs_size) and np.isfinite(obs).all()
    assert np.unique(obs, axis=0).shape[0] > RECORDED * 0.9  # states, not one repeated
    differences = max_differences(net, onnx_file, header, obs)
    assert max(differences.values()) <= PARITY, differences


@pytest.mark.parametrize("task", list(checkpoint.shipped_checkpoints()))
def test_pytorch_onnxruntime_and_c_agree_on_10000_recorded_observations(task, tmp_path):
    assert_three_forms_agree(CHECKPOINTS / f"{task}.pt", tmp_path)


@pytest.mark.parametrize("task", list(checkpoint.shipped_robust_checkpoints()))
def test_robust_policies_exports_agree_in_their_randomised_world(task, tmp_path):
    """The robust checkpoints observe the integral of their goal offset (37 values) and
    are recorded flying the world they were trained in: wind, delay, spread airframes."""
    source = checkpoint.shipped_robust_checkpoints()[task]
    net, config, _ = checkpoint.load(source)
    assert net.obs_size == F.OBS_SIZE + 3 and config.task_options["observe_integral"]
    assert_three_forms_agree(source, tmp_path)


@pytest.mark.parametrize("algo, preset", [("gae", "fast"), ("trpo", "fast"), ("ppo", "paper")])
def test_every_algorithm_and_preset_exports_the_same_function(algo, preset, tmp_path):
    """TRPO's separate critic, and the paper preset without observation normalisation."""
    config = make_config("hover", algo, preset)
    torch.manual_seed(1)
    net = ActorCritic(34, 4, config.hidden, algo != "trpo", config.normalize_obs, -0.5)
    net.norm.update(torch.randn(500, 34) * 0.3 + 0.1)  # statistics of some kind
    with torch.no_grad():
        net.policy_head.mean.weight.normal_(0.0, 0.3)  # beyond the init's small gain
    checkpoint.save(tmp_path / "net.pt", net, config)
    assert_three_forms_agree(tmp_path / "net.pt", tmp_path)


def test_a_network_with_a_fine_view_of_the_goal_exports_the_same_function(tmp_path):
    """fine_offset_scale: the exports compute tanh(goal offset / scale) inside, from the
    raw observation, as the network does (weighted here so that it moves the action)."""
    config = make_config("random_waypoint", "ppo", "fast", fine_offset_scale=0.25)
    torch.manual_seed(2)
    net = ActorCritic(34, 4, config.hidden, True, True, -0.5, fine_offset_scale=0.25)
    net.norm.update(torch.randn(500, 34) * 0.5)
    with torch.no_grad():
        net.actor_body[0].weight[:, 34:].normal_(0.0, 2.0)
        net.policy_head.mean.weight.normal_(0.0, 0.3)
    obs = torch.zeros(2, 34)
    obs[1, F.OBS_GOAL_POS] = torch.tensor([0.05, -0.05, 0.02])  # within the fine view's reach
    with torch.no_grad():
        assert torch.equal(net.inputs(obs)[:, 34:], torch.tanh(obs[:, F.OBS_GOAL_POS] / 0.25))
    action = net.mean_action(obs.numpy())
    assert np.abs(action[1] - action[0]).max() > 0.05  # the fine view moves the action
    checkpoint.save(tmp_path / "net.pt", net, config)
    assert_three_forms_agree(tmp_path / "net.pt", tmp_path)
    header = (tmp_path / "net.h").read_text()
    assert "#define POLICY_OBS_SIZE 34" in header and "#define POLICY_INPUT_SIZE 37" in header
    contract = json.loads(contract_path(tmp_path / "net.h").read_text())
    assert "tanh(obs[19:22] / 0.25 m)" in contract["observation"]["normalisation"]


# --- the C header ---------------------------------------------------------------------------
def test_c_header_is_c99_needs_only_tanhf_and_maps_actions_by_eq_19(tmp_path):
    header = export(CHECKPOINTS / "hover.pt", "c", tmp_path / "hover.h")[0]
    user = tmp_path / "user.c"  # a flight controller's file: the header and nothing else
    user.write_text(
        '#include "hover.h"\n'
        "void step(const float *obs, float *w) { float a[POLICY_ACT_SIZE];\n"
        "  policy_forward(obs, a); policy_rotor_speeds(a, w); }\n"
    )
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-c"]
    subprocess.run(["cc", *flags, "-o", str(tmp_path / "user.o"), str(user)], check=True)
    symbols = subprocess.run(
        ["nm", "-u", str(tmp_path / "user.o")], capture_output=True, text=True, check=True
    )
    assert symbols.stdout.split()[1::2] == ["tanhf"]  # no malloc, no other libm
    policy = CPolicy(header)
    action = np.array([0.0, 1.0, -100.0, 100.0], np.float32)
    engine = TaskEngine(TASKS["hover"], 1, TaskOptions())
    expected = engine.hover_speed + TaskOptions().beta * action
    expected = np.clip(expected, 0.0, PAPER.max_rotor_speed)
    np.testing.assert_allclose(policy.rotor_speeds(action), expected, rtol=1e-6)


def test_a_header_holding_other_code_is_refused_before_it_is_compiled(tmp_path, capsys):
    """A header is code: one that is not exactly what quadsitl export writes never runs."""
    header = export(CHECKPOINTS / "hover.pt", "c", tmp_path)[0]
    marker = tmp_path / "ran"
    header.write_text(
        header.read_text()
        + "#include <stdio.h>\n__attribute__((constructor)) static void evil(void) "
        + f'{{ fclose(fopen("{marker}", "w")); }}\n'
    )
    refused = "is not a header as quadsitl export writes it (refused: it would be compiled and run)"
    one_line_error(capsys, ("eval", str(header), "--episodes", "1"), refused)
    # Code in the contract, which the header's comment quotes: the two agree, and still no.
    header = export(CHECKPOINTS / "hover.pt", "c", tmp_path)[0]
    evil = (
        "hover */ int remove(const char *); __attribute__((constructor)) static void e(void) "
        f'{{ remove("{header}"); }} /*'
    )
    contract = json.loads(contract_path(header).read_text())
    contract["task"]["name"] = evil
    contract_path(header).write_text(json.dumps(contract))
    header.write_text(
        header.read_text().replace("quadsitl hover policy", f"quadsitl {evil} policy")
    )
    one_line_error(capsys, ("eval", str(header), "--episodes", "1"), refused)
    assert not marker.exists() and header.exists()


# --- the contract ---------------------------------------------------------------------------
def test_contract_states_the_codes_layout_frames_motors_and_normalisation(tmp_path):
    source = CHECKPOINTS / "target_follow.pt"
    written = export(source, "onnx", tmp_path)
    assert written == [tmp_path / "target_follow.onnx", tmp_path / "target_follow.contract.json"]
    contract = json.loads(written[1].read_text())
    options = TaskOptions()
    engine = TaskEngine(TASKS["target_follow"], 1, options)
    layout = contract["observation"]["layout"]
    columns = [c for block in layout for c in range(*block["columns"])]
    assert columns == list(range(engine.obs_size)) == list(range(contract["observation"]["size"]))
    by_start = {block["columns"][0]: block for block in layout}
    assert "body FLU" in by_start[F.OBS_BODY_VEL.start]["frame_unit"]
    assert "world ENU" in by_start[F.OBS_GOAL_POS.start]["frame_unit"]
    assert "target velocity" in by_start[F.OBS_TARGET_VELOCITY.start]["meaning"]
    assert contract["conventions"]["quaternion_order_in_state"] == "(w, x, y, z)"
    action = contract["action"]
    assert action["hover_rotor_speed_rad_s"] == engine.hover_speed
    assert action["beta_rad_s"] == options.beta
    assert action["action_bounds"] == [engine.action_low, engine.action_high]
    assert contract["control"]["rate_hz"] == 1 / options.control_period
    motors = contract["motors"]["order"]
    positions = [m["position_body_flu_m"] for m in motors]
    assert positions == PAPER.rotor_positions().tolist()
    assert [m["reaction_torque_sign_z"] for m in motors] == list(PAPER.rotor_yaw_sign)
    assert contract["checkpoint"]["sha256"] == hashlib.sha256(source.read_bytes()).hexdigest()
    assert "feed raw observations" in contract["observation"]["normalisation"]
    # The same contract for the C form (one file serves both).
    export(source, "c", tmp_path)
    assert json.loads(written[1].read_text()) == contract


def test_contract_tells_to_feed_zero_position_to_a_policy_trained_without_it(tmp_path):
    """The waypoint policy was trained with observe_position false: its contract says the
    position slots are not used, and the hover policy's says nothing of the kind."""
    for task, hidden in (("random_waypoint", True), ("hover", False)):
        contract = json.loads(export(CHECKPOINTS / f"{task}.pt", "onnx", tmp_path)[1].read_text())
        position = contract["observation"]["layout"][0]
        assert position["columns"] == [F.OBS_POS.start, F.OBS_POS.stop]
        assert ("NOT USED by this policy" in position["meaning"]) is hidden, position


def test_contract_layout_describes_what_the_env_observes():
    """A vehicle pitched 30° nose down, flying 2 m/s east, 1 m north of the origin: each
    block of the observation is what its contract line says."""
    engine = TaskEngine(TASKS["hover"], 1, TaskOptions())
    state = np.zeros((1, L.STATE_SIZE))
    state[0, L.POS] = [0.0, 1.0, 0.0]
    state[0, L.VEL] = [2.0, 0.0, 0.0]  # world ENU
    state[0, L.QUAT] = quat_from_euler(0.0, np.radians(30.0), 0.0)  # roll, pitch, yaw
    state[0, L.ROTORS] = PAPER.hover_rotor_speed
    obs, dist, tilt = F.empty_buffers(1)
    F.observe(state, engine.fleet.params[:1], np.zeros((1, 6)), obs, dist, tilt)
    np.testing.assert_allclose(obs[0, F.OBS_POS], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(obs[0, F.OBS_SIN], [0.0, 0.5, 0.0], atol=1e-7)
    forward = 2.0 * np.cos(np.radians(30.0))  # body FLU: forward, and up along the body
    np.testing.assert_allclose(obs[0, F.OBS_BODY_VEL], [forward, 0.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(obs[0, F.OBS_ROTORS], np.sqrt(0.5), rtol=1e-6)
    np.testing.assert_allclose(obs[0, F.OBS_GOAL_POS], [0.0, -1.0, 0.0])


# --- flown in the loop ----------------------------------------------------------------------
def test_eval_gives_the_checkpoints_success_rate_for_its_exports(tmp_path, capsys):
    source = CHECKPOINTS / "land.pt"
    files = [source, export(source, "onnx", tmp_path)[0], export(source, "c", tmp_path)[0]]
    capsys.readouterr()
    reports = []
    for path in files:
        assert main(["eval", str(path), "--episodes", "6"]) == 0
        reports.append(capsys.readouterr().out.splitlines())
    assert reports[0][-1].startswith("success_rate: ")
    assert reports[1] == reports[0] and reports[2] == reports[0]  # every figure alike


@pytest.mark.parametrize("form", ["onnx", "c"])
def test_exported_waypoint_policy_flies_take_off_and_goto_as_the_checkpoint_does(form, tmp_path):
    from policies.autopilot import PolicyAutopilot
    from quadsitl.flight_software.vehicle import Vehicle

    torch.set_num_threads(1)
    source = CHECKPOINTS / "random_waypoint.pt"
    exported = export(source, form, tmp_path)[0]
    tracks = []
    for path in (source, exported):
        vehicle = Vehicle(autopilot=PolicyAutopilot.from_checkpoint(str(path), PAPER))
        assert vehicle.arm().ok and vehicle.takeoff(3.0).ok
        for _ in range(6_000):
            vehicle.step()
        assert vehicle.reposition(6.0, 4.0, 3.0, None, None).ok  # a 7.2 m leg: carrots
        track = []
        for _ in range(10_000):
            vehicle.step()
            track.append(vehicle.position.copy())
        assert not vehicle.crashed
        tracks.append(np.array(track))
    target = np.array([6.0, 4.0, 3.0 + PAPER.gear_height])
    assert np.linalg.norm(tracks[1][-1] - target) < 0.2
    assert np.abs(tracks[1] - tracks[0]).max() < 0.01  # m: the same flight


def test_sim_flies_with_an_onnx_autopilot(tmp_path):
    onnx_file = export(CHECKPOINTS / "hover.pt", "onnx", tmp_path)[0]
    common = ("sim", "--gcs", "udpin:127.0.0.1:0", "--api", "none", "--logs", "none")
    flown = run_cli(*common, "--duration", "1", "--autopilot", str(onnx_file))
    assert flown.returncode == 0, flown.stderr
    assert flown.stdout.splitlines()[1] == (
        f"quadsitl sim: flown by the policy in {onnx_file}, not the cascaded controller"
    )


@pytest.mark.slow
@pytest.mark.parametrize("form", ["onnx", "c"])
def test_ground_station_mission_flown_by_an_exported_autopilot(form, tmp_path):
    """The demo mission (take-off, a 15 m square with a climb, land) as the checkpoint
    flies it (tests/test_policies.py)."""
    from gcs_tools.scripted_flight import fly_mission

    exported = export(CHECKPOINTS / "random_waypoint.pt", form, tmp_path)[0]
    options = "--logs none --speed 4 --autopilot"
    with sim_with_client(options, exported, connect_timeout=40) as (client, _):
        report = fly_mission(client, timeout=60)
    assert report.landed
    assert max(report.waypoint_errors) < 0.3


# --- bad input: one line, nothing written ---------------------------------------------------
def one_line_error(capsys, args: tuple[str, ...], *phrases: str) -> None:  # type: ignore[no-untyped-def]
    """``quadsitl ARGS`` (in this process: the command line's own error path) exits 2
    with one line on stderr holding ``phrases``."""
    with pytest.raises(SystemExit) as exited:
        main(list(args))
    stderr = capsys.readouterr().err
    assert exited.value.code == 2, stderr
    assert stderr.count("\n") == 1, stderr
    for phrase in phrases:
        assert phrase in stderr, stderr


def test_export_refuses_bad_input_with_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    foreign = tmp_path / "pendulum.pt"  # a real checkpoint, of a Gymnasium env
    checkpoint.save(foreign, ActorCritic(3, 1), make_config("Pendulum-v1", "ppo", "fast"))
    wrong_shape = tmp_path / "wide.pt"  # says hover, maps 20 observations
    checkpoint.save(wrong_shape, ActorCritic(20, 4), make_config("hover", "ppo", "fast"))
    hover = str(CHECKPOINTS / "hover.pt")
    cases = [
        (("export", hover, "--format", "tflite", "-o", str(out)), "unknown format 'tflite'"),
        (("export", hover, "--format", "onnx", "-o", str(out / "no/such.onnx")), "no folder"),
        (("export", hover, "--format", "c", "-o", str(out / "hover.onnx")), "to a .h file"),
        (("export", hover, "--format", "c", "-o", str(out / "fc")), "(a folder to write into: end"),
        (("export", hover, "--format", "c", "-o", f"{junk}/"), "is a file, not a folder"),
        (("export", str(junk), "--format", "onnx", "-o", str(out)), "not a quadsitl checkpoint"),
        (("export", str(foreign), "--format", "c", "-o", str(out)), "not a quadsitl task"),
        (("export", str(wrong_shape), "--format", "onnx", "-o", str(out)), "maps 20 obs"),
        (("export", str(tmp_path / "none.pt"), "--format", "c", "-o", str(out)), "no checkpoint"),
    ]
    for args, phrase in cases:
        one_line_error(capsys, args, "quadsitl export: error: ", phrase)
    assert list(out.iterdir()) == []


def px4_layout_onnx(path: Path) -> None:
    """An ONNX policy of another layout (PX4's 15 inputs), not written by quadsitl."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    weight = numpy_helper.from_array(np.zeros((15, 4), np.float32), "w")
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "w"], ["action"])],
        "px4",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", 15])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", 4])],
        [weight],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def test_exported_files_that_do_not_fit_are_refused_naming_the_layout(tmp_path, capsys):
    px4 = tmp_path / "px4.onnx"
    px4_layout_onnx(px4)
    one_line_error(
        capsys,
        ("eval", str(px4), "--task", "hover", "--episodes", "1"),
        "takes 15 observations; the hover task gives 34: [0:3] position relative to the task "
        "origin (world ENU, m); [3:6] sin(roll, pitch, yaw)",
    )
    one_line_error(capsys, ("eval", str(px4), "--episodes", "1"), "no quadsitl contract", "--task")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"\x00not onnx")
    one_line_error(capsys, ("eval", str(junk), "--episodes", "1"), "not an ONNX model")
    header = export(CHECKPOINTS / "hover.pt", "c", tmp_path)[0]
    contract_path(header).unlink()
    one_line_error(capsys, ("eval", str(header), "--episodes", "1"), "needs its contract")
    follow = export(CHECKPOINTS / "target_follow.pt", "onnx", tmp_path)[0]
    sim = run_cli("sim", "--logs", "none", "--duration", "1", "--autopilot", str(follow))
    assert sim.returncode == 2 and len(sim.stderr.splitlines()) == 1
    assert sim.stderr.startswith(
        "quadsitl sim: error: a target_follow policy cannot fly goto and mission legs (it "
    )
    assert sim.stderr.endswith("--autopilot takes a hover or waypoint policy\n")
    bare = tmp_path / "bare.onnx"  # a quadsitl export stripped of its contract: foreign
    shutil.copyfile(export(CHECKPOINTS / "hover.pt", "onnx", tmp_path)[0], bare)
    import onnx

    model = onnx.load(str(bare))
    del model.metadata_props[:]
    onnx.save(model, str(bare))
    policy, config = load_policy(bare, "hover")
    assert config.task == "hover" and policy.obs_size == 34


def _run_checkpoint(runs: Path, run: str) -> Path:
    """A copy of the shipped hover policy where training writes a run's best.pt."""
    best = runs / run / "checkpoints" / "best.pt"
    best.parent.mkdir(parents=True)
    shutil.copy(CHECKPOINTS / "hover.pt", best)
    return best


def test_export_into_a_folder_makes_it_as_the_docs_type_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    hover = str(CHECKPOINTS / "hover.pt")
    assert main(["export", hover, "--format", "c", "-o", "fc/"]) == 0  # docs/training.md
    assert sorted(p.name for p in (tmp_path / "fc").iterdir()) == [
        "hover.contract.json",
        "hover.h",
    ]
    assert main(["export", hover, "--format", "c", "-o", "deep/er/"]) == 0  # made, nested
    assert (tmp_path / "deep" / "er" / "hover.h").is_file()
    assert main(["export", hover, "--format", "c", "-o", "fc"]) == 0  # existing: into it
    assert main(["export", hover, "--format", "c", "-o", "fc/named.h"]) == 0  # as given
    assert (tmp_path / "fc" / "named.h").is_file()
    assert "quadsitl eval fc/hover.h" in capsys.readouterr().out


def test_an_export_is_named_after_its_run(tmp_path, monkeypatch, capsys):
    """Two runs' best.pt export to two files, not both to best.onnx."""
    monkeypatch.chdir(tmp_path)
    first = _run_checkpoint(tmp_path / "runs", "hover-ppo-fast-seed0")
    second = _run_checkpoint(tmp_path / "runs", "hover-ppo-fast-seed1")
    out = tmp_path / "out"
    written = [export(source, "c", f"{out}/")[0] for source in (first, second)]
    assert [p.name for p in written] == [
        "hover-ppo-fast-seed0-best.h",
        "hover-ppo-fast-seed1-best.h",
    ]
    assert contract_path(written[0]).is_file()
    assert export(first, "c")[0] == Path("hover-ppo-fast-seed0-best.h")  # the default
    assert export(first, "c", out / "mine.h")[0].name == "mine.h"  # an explicit name kept
    monkeypatch.chdir(first.parent.parent)  # in the run folder: checkpoints/best.pt
    assert export(Path("checkpoints/best.pt"), "c")[0].name == "hover-ppo-fast-seed0-best.h"


def test_robustness_tells_two_runs_best_checkpoints_apart(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    runs = tmp_path / "runs"
    sources = [str(_run_checkpoint(runs, f"hover-ppo-fast-seed{s}")) for s in (0, 1)]
    args = ["robustness", *sources, "--axes", "target", "--episodes", "1", "--out", "ladder"]
    assert main(args) == 0
    table = (tmp_path / "ladder" / "robustness.md").read_text()
    assert "### hover-ppo-fast-seed0-best (hover" in table
    assert "### hover-ppo-fast-seed1-best (hover" in table
