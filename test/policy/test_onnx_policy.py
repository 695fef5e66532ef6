"""Export contract: ONNX actions equal the torch policy's; OnnxPolicy refuses bad files."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

import vmas_ros
from vmas_ros.envs.torchrl_env import TorchRLEnv
from vmas_ros.policy import OnnxPolicy
from vmas_ros.policy.onnx_policy import sha256_of_file
from vmas_ros.train.algorithms import build_agent
from vmas_ros.train.config import TrainConfig
from vmas_ros.train.export import describe_env, export_policy

ALGORITHMS = ["cppo", "mappo", "ippo", "hetippo"]


def _agent_and_env(algorithm, scenario="balance", num_envs=6):
    env = vmas_ros.make_env(scenario, num_envs=num_envs, seed=1)
    info = describe_env(env)
    config = TrainConfig(scenario=scenario, algorithm=algorithm, num_cells=32)
    torch.manual_seed(3)
    agent = build_agent(config, len(info["agents"]), info["observation_size"], info["action_size"],
                        torch.tensor(info["action_low"]), torch.tensor(info["action_high"]))
    return agent, env, info


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A MAPPO export of balance, copied fresh into each test that tampers with it."""
    agent, env, info = _agent_and_env("mappo")
    out = tmp_path_factory.mktemp("export")
    export_policy(agent.actor_network, info, "balance", {"n_agents": 3}, "mappo", out / "policy")
    return out


@pytest.fixture
def files(exported, tmp_path):
    for name in ("policy.onnx", "policy.json"):
        shutil.copy(exported / name, tmp_path / name)
    return tmp_path / "policy.onnx", tmp_path / "policy.json"


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_onnx_matches_torch_deterministic_policy(algorithm, tmp_path):
    agent, env, info = _agent_and_env(algorithm)
    tenv = TorchRLEnv(env)
    td = tenv.reset()
    # move the world a bit so observations are not the symmetric initial ones
    for _ in range(3):
        td = tenv.rand_step(td).get("next")
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        torch_action = agent.policy(td)[("agents", "action")].numpy()
    onnx_path, json_path = export_policy(agent.actor_network, info, "balance", {}, algorithm, tmp_path / "p")
    policy = OnnxPolicy.load(onnx_path)
    onnx_action = policy.act(td[("agents", "observation")].numpy())
    assert onnx_action.shape == torch_action.shape == (6, 3, 2)
    np.testing.assert_allclose(onnx_action, torch_action, atol=1e-5)
    # dynamic batch and the single-sample form
    single = policy.act(td[("agents", "observation")][2].numpy())
    np.testing.assert_allclose(single, torch_action[2], atol=1e-5)
    assert policy.act(np.zeros((1, 3, info["observation_size"]), np.float32)).shape == (1, 3, 2)


def test_metadata_contents(files):
    onnx_path, json_path = files
    meta = json.loads(json_path.read_text())
    assert meta["format"] == "vmas_ros.policy" and meta["version"] == 1
    assert meta["agents"] == ["agent_0", "agent_1", "agent_2"]
    assert meta["observation_size"] == 16 and meta["action_size"] == 2
    assert meta["action_low"] == [-1.0, -1.0] and meta["action_high"] == [1.0, 1.0]
    assert meta["onnx_file"] == "policy.onnx" and meta["onnx_sha256"] == sha256_of_file(onnx_path)
    assert meta["scenario_kwargs"] == {"n_agents": 3} and meta["created_by"] == f"vmas_ros {vmas_ros.__version__}"
    policy = OnnxPolicy.load(json_path)
    actions = policy.act(np.random.default_rng(0).normal(size=(50, 3, 16)) * 10)
    assert actions.dtype == np.float32 and (actions >= -1).all() and (actions <= 1).all()


def _edit(json_path, **changes):
    meta = json.loads(json_path.read_text())
    for key, value in changes.items():
        if value is KeyError:
            del meta[key]
        else:
            meta[key] = value
    json_path.write_text(json.dumps(meta))


@pytest.mark.parametrize("changes, message", [
    ({"onnx_sha256": KeyError}, "missing key.*onnx_sha256"),
    ({"version": 2}, "unsupported 'version' 2"),
    ({"version": "1"}, "'version' must be an int, got '1'"),
    ({"format": "other"}, "'format' is 'other', expected 'vmas_ros.policy'"),
    ({"observation_size": True}, "'observation_size' must be an int"),
    ({"agents": []}, "'agents' must be a non-empty list"),
    ({"action_low": [-1.0]}, "'action_low' has 1 values, expected action_size=2"),
    ({"action_low": [2.0, -1.0]}, "action_low > action_high at index"),
    ({"action_type": "discrete"}, "'action_type' is 'discrete'"),
    ({"onnx_file": "../x.onnx"}, "bare file name"),
    ({"onnx_sha256": "0" * 64}, "SHA-256 is [0-9a-f]{64}, but policy.json expects 0000"),
])
def test_refuses_bad_metadata(files, changes, message):
    _, json_path = files
    _edit(json_path, **changes)
    with pytest.raises(ValueError, match=message):
        OnnxPolicy.load(json_path)


def test_refuses_tampered_onnx(files):
    onnx_path, json_path = files
    data = bytearray(onnx_path.read_bytes())
    data[-10] ^= 0xFF
    onnx_path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="SHA-256.*modified"):
        OnnxPolicy.load(onnx_path)


@pytest.mark.parametrize("key, value, message", [
    ("observation_size", 17, "input 'observation' has shape .* expected \\[batch, 3 \\(agents\\), 17"),
    ("action_size", 3, "output 'action' has shape .* expected \\[batch, 3 \\(agents\\), 3"),
    ("agents", ["a", "b"], "expected \\[batch, 2 \\(agents\\)"),
])
def test_refuses_metadata_that_does_not_match_the_graph(files, key, value, message):
    _, json_path = files
    changes = {key: value}
    if key == "action_size":
        changes.update(action_low=[-1.0] * 3, action_high=[1.0] * 3)
    _edit(json_path, **changes)
    with pytest.raises(ValueError, match=message):
        OnnxPolicy.load(json_path)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_refuses_wrong_io_names(tmp_path):
    class Net(torch.nn.Module):
        def forward(self, x):
            return x[..., :2]

    onnx_path = tmp_path / "p.onnx"
    torch.onnx.export(Net(), (torch.zeros(1, 3, 16),), str(onnx_path), input_names=["obs"], output_names=["action"],
                      dynamic_axes={"obs": {0: "b"}}, dynamo=False)
    meta = {"format": "vmas_ros.policy", "version": 1, "scenario": "balance", "scenario_kwargs": {},
            "algorithm": "mappo", "agents": ["agent_0", "agent_1", "agent_2"], "observation_size": 16,
            "action_size": 2, "action_low": [-1.0, -1.0], "action_high": [1.0, 1.0], "action_type": "continuous",
            "onnx_file": "p.onnx", "onnx_sha256": sha256_of_file(onnx_path), "created_by": "test"}
    (tmp_path / "p.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="ONNX inputs are \\['obs'\\], expected exactly \\['observation'\\]"):
        OnnxPolicy.load(tmp_path / "p.json")


def test_refuses_missing_files_and_bad_paths(files, tmp_path):
    onnx_path, json_path = files
    with pytest.raises(ValueError, match="must end in .json or .onnx"):
        OnnxPolicy.load(tmp_path / "policy.pt")
    with pytest.raises(ValueError, match="does not exist"):
        OnnxPolicy.load(tmp_path / "nothing.json")
    onnx_path.unlink()
    with pytest.raises(ValueError, match="ONNX file .* does not exist"):
        OnnxPolicy.load(json_path)
    json_path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        OnnxPolicy.load(json_path)


def test_act_validates_shapes(files):
    policy = OnnxPolicy.load(files[1])
    for bad in (np.zeros((4, 2, 16)), np.zeros((4, 3, 15)), np.zeros(16), np.zeros((0, 3, 16))):
        with pytest.raises(ValueError, match="observation"):
            policy.act(bad)
    with pytest.raises(ValueError, match="NaN or inf"):
        policy.act(np.full((3, 16), np.nan))
    with pytest.raises(ValueError, match="numeric"):
        policy.act(np.array([["a"] * 16] * 3))


def test_export_refuses_heterogeneous_agents():
    env = vmas_ros.make_env("simple_adversary", num_envs=2)
    with pytest.raises(ValueError, match="different observation sizes \\(adversary_0=8, agent_0=10"):
        describe_env(env)


def test_onnx_policy_module_does_not_import_torch(files):
    """The deployment side must run with torch absent: block it and load the module file directly."""
    module = Path(vmas_ros.__file__).parent / "policy" / "onnx_policy.py"
    code = (
        "import sys, importlib.util, numpy as np\n"
        "sys.modules['torch'] = None\n"
        f"spec = importlib.util.spec_from_file_location('onnx_policy', {str(module)!r})\n"
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
        f"p = m.OnnxPolicy.load({str(files[1])!r})\n"
        "print(p.act(np.zeros((2, 3, 16), np.float32)).shape)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "(2, 3, 2)"
