"""``vmas_ros.testing.vmas_states``: the shipped scenarios' default ``scenario_state`` hooks.

That each hook makes its scenario agree with VMAS is
test_check_scenario.py's run over every shipped scenario; here, that the
table names real scenarios on both sides, and that a hook writes VMAS's draw
into ours without changing what ours keeps (shape, dtype, device).
"""
from __future__ import annotations

import pytest

from vmas_ros.scenarios import REGISTRY
from vmas_ros.testing import parity, vmas_states
from vmas_ros.testing.state import capture_kept


def test_every_hook_is_named_after_a_shipped_scenario_vmas_also_has():
    import vmas

    in_vmas = set(vmas.scenarios) | set(vmas.debug_scenarios) | set(vmas.mpe_scenarios)
    assert set(vmas_states.SCENARIO_STATES) <= set(REGISTRY) & in_vmas
    for name, hook in vmas_states.SCENARIO_STATES.items():
        assert hook.__name__ == name and hook.__doc__, name


@pytest.mark.parametrize("name", ["navigation", "flocking", "simple_reference", "joint_passage_size", "het_mass"])
def test_a_hook_writes_vmas_draw_into_ours_keeping_its_layout(name, device):
    """Per agent [B] tensors stacked as ours keeps them ([B, n], or agent-major [n, B] for flocking),
    one landmark for the batch as an index per env, masses as floats: values change, layouts do not."""
    import vmas_ros

    num_envs = 5  # differs from every agent count here, so a transposed copy would show in the shapes
    up = parity.make_vmas_env(name, num_envs, device, seed=1)
    ours = vmas_ros.make_env(name, num_envs=num_envs, device=device, seed=2)
    before = capture_kept(ours)
    masses = [agent.mass for agent in ours.agents]
    parity.copy_start(up, ours, vmas_states.SCENARIO_STATES[name])
    after = capture_kept(ours)
    assert list(after) == list(before)
    for path, value in after.items():
        assert (value.shape, value.dtype, value.device) == (before[path].shape, before[path].dtype,
                                                            before[path].device), path
    changed = [path for path, value in after.items() if not value.equal(before[path])]
    if name == "het_mass":
        assert [agent.mass for agent in ours.agents] == [agent.mass for agent in up.agents] != masses
    else:
        assert changed, f"{name}: the hook changed none of the tensors ours keeps"
