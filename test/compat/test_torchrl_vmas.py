"""TorchRL's own ``VmasEnv``, unchanged, on vmas_ros through ``install_as_vmas()``.

Every scenario passes TorchRL's ``check_env_specs``.

One fresh interpreter builds every scenario, continuous and discrete (the alias
is process-wide, and this test process has the real ``vmas`` imported), and
reports each failure by scenario and action kind.
"""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

CHECK_ALL = """
    import json, sys
    import vmas_ros
    vmas_ros.install_as_vmas()
    import torch
    from torchrl.envs.libs import vmas as torchrl_vmas
    from torchrl.envs.utils import check_env_specs

    torch.manual_seed(0)
    report = {"has_vmas": torchrl_vmas._has_vmas, "available": sorted(torchrl_vmas.VmasEnv.available_envs),
              "failures": {}, "checked": 0, "env_types": set()}
    for continuous in (True, False):
        for name in vmas_ros.list_scenarios():
            try:
                env = torchrl_vmas.VmasEnv(scenario=name, num_envs=2, continuous_actions=continuous, seed=0)
                check_env_specs(env, seed=0)
                report["env_types"].add(f"{type(env._env).__module__}.{type(env._env).__name__}")
                report["checked"] += 1
            except Exception as error:  # every scenario is tried; the test lists them all
                kind = "continuous" if continuous else "discrete"
                report["failures"][f"{name} ({kind})"] = f"{type(error).__name__}: {error}"[:400]
    report["env_types"] = sorted(report["env_types"])
    print("REPORT" + json.dumps(report))
"""


def test_torchrl_vmasenv_check_env_specs_for_every_scenario(tmp_path):
    import vmas_ros

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(CHECK_ALL)], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 0, f"subprocess failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    line = next(line for line in done.stdout.splitlines() if line.startswith("REPORT"))
    report = json.loads(line[len("REPORT"):])
    names = sorted(vmas_ros.scenarios + vmas_ros.debug_scenarios + vmas_ros.mpe_scenarios)  # tests may register more
    assert len(names) == 41, names
    assert report["has_vmas"] is True
    assert sorted(names) == report["available"]  # TorchRL lists our scenarios, read from `vmas`
    failures = "\n".join(f"  {case}: {message}" for case, message in sorted(report["failures"].items()))
    assert not report["failures"], f"{len(report['failures'])} of {2 * len(names)} VmasEnv cases failed:\n{failures}"
    assert report["checked"] == 2 * len(names)
    assert report["env_types"] == ["vmas_ros.envs.environment.Environment"], report["env_types"]
