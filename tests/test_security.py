"""Safe by default: a checkpoint is data and runs no code, the vehicle can be reached
from this host only unless asked, and an empty secret is an error."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import torch

from gcs_tools.demo import free_udp_port
from policies import checkpoint
from policies.config import make_config
from policies.networks import ActorCritic
from tests.conftest import interrupt, run_cli, socket_addresses, start_quiet_sim

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "checkpoints" / "hover.pt"


# --- 1. a checkpoint is data ------------------------------------------------------------
class Payload:
    """Pickles to a call of os.system: what a hostile checkpoint would hold."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch {self.marker}",))


def _valid_payload() -> dict:
    return torch.load(SHIPPED, weights_only=True)


def test_a_checkpoint_that_would_run_code_is_refused_and_runs_nothing(tmp_path):
    marker = tmp_path / "pwned"
    evil = tmp_path / "evil.pt"
    payload = _valid_payload()
    payload["iteration"] = Payload(marker)
    torch.save(payload, evil)
    with pytest.raises(ValueError, match="not a quadsitl checkpoint, or holds more than data"):
        checkpoint.load(evil)
    result = run_cli("eval", str(evil), "--episodes", "2")
    assert result.returncode == 2 and "holds more than data" in result.stderr
    assert "success_rate" not in result.stdout and "Traceback" not in result.stderr
    sim = run_cli("sim", "--autopilot", str(evil), "--duration", "1", "--logs", "none")
    assert sim.returncode == 2 and "holds more than data" in sim.stderr
    assert not marker.exists()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: p.pop("state_dict"), "missing state_dict"),
        (
            lambda p: p["config"].update(learning_rat=1.0),
            r"unknown config key\(s\) \['learning_rat",
        ),
        (lambda p: p.update(obs_size=-3), "obs_size must be an integer in 1"),
        (lambda p: p["config"].update(hidden=-128), "hidden must be an integer ≥ 1"),
        (
            lambda p: p.update(obs_size=30),
            r"\['norm.mean'\] has shape \(34,\), the network needs \(30,\)",
        ),
        (lambda p: p["state_dict"].pop("value_head.bias"), r"missing \['value_head.bias'\]"),
        (lambda p: p["state_dict"]["value_head.bias"].fill_(float("nan")), "NaN or infinite"),
        (lambda p: p.update(two_headed="yes"), "two_headed must be true or false"),
        (
            lambda p: p["config"].update(fine_offset_scale=-0.25),
            r"fine_offset_scale must be a number in \[0, 100\]",
        ),
        (  # a fine view the weights were not trained with
            lambda p: p["config"].update(fine_offset_scale=0.25),
            r"\['actor_body.0.weight'\] has shape \(128, 34\), the network needs \(128, 37\)",
        ),
    ],
)
def test_checkpoint_schema_errors_name_the_problem(tmp_path, change, message):
    payload = _valid_payload()
    change(payload)
    path = tmp_path / "bad.pt"
    torch.save(payload, path)
    with pytest.raises(ValueError, match=message):
        checkpoint.load(path)


def test_saved_checkpoints_hold_only_data(tmp_path):
    net = ActorCritic(34, 4)
    optimizer = torch.optim.Adam(net.parameters())
    net.value(torch.zeros(1, 34)).sum().backward()
    optimizer.step()
    config = make_config("hover", "ppo", "fast")
    optimizers = [optimizer.state_dict()]
    checkpoint.save(tmp_path / "c.pt", net, config, iteration=3, optimizers=optimizers)
    _, loaded_config, payload = checkpoint.load(tmp_path / "c.pt")  # weights_only
    assert loaded_config == config and payload["iteration"] == 3
    assert payload["optimizers"][0]["state"]  # the optimiser state survives


# --- 2, 3. loopback by default; an empty secret is an error ---------------------------
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_default_simulator_binds_only_loopback_and_says_signing_is_off():
    process = start_quiet_sim()
    try:
        banner = process.stdout.readline()  # printed once the links are open
        addresses = socket_addresses(process.pid)
    finally:
        _out, err = interrupt(process)
    assert "signing off" in banner
    assert len(addresses) >= 2  # the GCS and API links
    loopback = "0100007F"  # 127.0.0.1 as /proc/net writes it
    assert all(a == loopback for a in addresses), addresses
    assert "can be reached from other hosts" not in err


def test_listening_on_all_interfaces_without_signing_warns():
    port = free_udp_port()
    process = start_quiet_sim("--gcs", f"udpin:0.0.0.0:{port}", "--api", "none")
    try:
        process.stdout.readline()
    finally:
        _out, err = interrupt(process)
    assert f"gcs (udpin:0.0.0.0:{port}) can be reached from other hosts and signing is off" in err


@pytest.mark.parametrize(
    ("args", "env"),
    [
        (["--signing-passphrase", ""], {}),
        (["--signing-passphrase", "   "], {}),
        ([], {"QUADSITL_SIGNING_PASSPHRASE": ""}),
        ([], {"QUADSITL_SIGNING_KEY": ""}),
        ([], {"QUADSITL_SIGNING_KEY": "00" * 32}),
    ],
)
def test_an_empty_secret_is_an_error(args, env):
    result = run_cli("sim", "--logs", "none", "--duration", "5", *args, env=env, timeout=30)
    assert result.returncode == 2, result.stdout
    assert "empty" in result.stderr or "64 hexadecimal" in result.stderr or "zeros" in result.stderr
    assert "Traceback" not in result.stderr


def test_banner_says_signing_is_on():
    process = start_quiet_sim("--signing-passphrase", "a real secret")
    try:
        banner = process.stdout.readline()
    finally:
        interrupt(process)
    assert "signing on" in banner
