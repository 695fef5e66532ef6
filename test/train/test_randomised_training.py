"""`vmas-ros train --randomisation`: the settings reach the envs and are recorded with the exported policy."""
import json

from vmas_ros.cli import main
from vmas_ros.envs.randomisation import Randomisation

SETTINGS = {"command_latency": [0.0, 0.1], "actuator_lag": 0.05, "position_noise": [0.0, 0.01], "mass_scale": [0.9, 1.1]}
TINY = ["--scenario", "navigation", "--scenario-kwargs", '{"n_agents": 2}', "--iterations", "1",
        "--frames-per-batch", "200", "--num-envs", "20", "--max-steps", "10", "--minibatch-size", "100",
        "--epochs", "1", "--num-cells", "16", "--depth", "1", "--eval-episodes", "0", "--quiet"]


def test_a_randomised_run_records_its_settings_with_the_policy(tmp_path):
    out = tmp_path / "run"
    assert main(["train", *TINY, "--randomisation", json.dumps(SETTINGS), "--out", str(out)]) == 0
    assert json.loads((out / "config.json").read_text())["randomisation"] == SETTINGS
    recorded = json.loads((out / "policy.json").read_text())["randomisation"]
    assert recorded == Randomisation.from_dict(SETTINGS).to_dict()
    assert recorded["command_latency"] == [0.0, 0.1] and recorded["drag_scale"] == [1.0, 1.0]
    assert main(["export", "--checkpoint", str(out), "--out", str(tmp_path / "again")]) == 0
    assert json.loads((tmp_path / "again.json").read_text())["randomisation"] == recorded


def test_a_bad_setting_is_refused_before_training(tmp_path, capsys):
    assert main(["train", *TINY, "--randomisation", '{"lag": 0.1}', "--out", str(tmp_path / "bad")]) == 2
    assert "unknown randomisation settings ['lag']" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
