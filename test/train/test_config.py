"""TrainConfig: file loading, validation, and flag precedence."""
import argparse
import json

import pytest

from vmas_ros.train.cli import add_train_arguments, config_from_args
from vmas_ros.train.config import TrainConfig, load_config_file


def _parse(*argv):
    parser = argparse.ArgumentParser()
    add_train_arguments(parser)
    return parser.parse_args(list(argv))


def test_defaults_are_valid_and_documented():
    config = TrainConfig()
    assert config.steps_per_batch * config.num_envs == config.frames_per_batch
    from dataclasses import fields
    assert all(f.metadata.get("help") for f in fields(TrainConfig))


def test_yaml_file_then_flags_override(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("scenario: simple\nalgorithm: ippo\nlambda: 0.8\nlr: 1\nscenario_kwargs: {a: 1}\n")
    config, state = config_from_args(_parse("--config", str(path), "--lr", "0.01", "--no-gif"))
    assert state is None
    assert (config.scenario, config.algorithm, config.lmbda, config.lr, config.gif) == ("simple", "ippo", 0.8, 0.01, False)
    assert isinstance(config.lr, float) and config.scenario_kwargs == {"a": 1}


def test_json_file(tmp_path):
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"num-envs": 10, "frames_per_batch": 100, "minibatch_size": 50}))
    assert load_config_file(path)["num-envs"] == 10
    config, _ = config_from_args(_parse("--config", str(path)))
    assert config.num_envs == 10 and config.steps_per_batch == 10


@pytest.mark.parametrize("values, message", [
    ({"algorithm": "dqn"}, "algorithm must be one of"),
    ({"frames_per_batch": 100, "num_envs": 30}, "multiple of num_envs"),
    ({"minibatch_size": 10**9}, "minibatch_size"),
    ({"learning_rate": 1.0}, "unknown key\\(s\\) \\['learning_rate'\\]"),
    ({"gamma": 1.5}, "gamma must be in"),
    ({"epochs": "3"}, "epochs must be int"),
    ({"lambda": 0.9, "lmbda": 0.9}, "either 'lambda' or 'lmbda'"),
])
def test_bad_values_are_refused(values, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig.from_dict(values)


def test_bad_flag_values_exit_cleanly(capsys):
    from vmas_ros.cli import main

    assert main(["train", "--frames-per-batch", "100", "--num-envs", "30", "--out", "/nonexistent/x"]) == 2
    assert "multiple of num_envs" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _parse("--algorithm", "dqn")
