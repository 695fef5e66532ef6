"""``vmas_ros.testing.parity``: the start copies everything a step depends on.

Besides entity states and the scenario's own tensors, two hidden pieces
decide a step: the angle a ``rotate=False`` joint holds between its end and
the rod (re-taken by the engine whenever an end is moved by hand) and the
random stream observation noise is drawn from.
"""
from __future__ import annotations

import torch

import vmas_ros
from vmas_ros.testing import parity, vmas_states
from vmas_ros.testing.rollout import space_actions


def test_copy_state_keeps_the_angles_vmas_joints_hold():
    """waterfall's last joint does not let its ends turn. Copying VMAS's state into ours moves the ends,
    which makes ours hold the drifted angle; copy_state puts VMAS's back, so that a comparison restarted
    from VMAS's state every step (``resync``) agrees (it drifted away at the second step before)."""
    up, ours = parity.make_vmas_env("waterfall", 4), vmas_ros.make_env("waterfall", num_envs=4)
    parity.copy_start(up, ours)
    gen = torch.Generator().manual_seed(0)
    actions = space_actions(ours, gen)
    up.step([a.clone() for a in actions])
    ours.step([a.clone() for a in actions])
    parity.copy_state(up, ours)
    held = {frozenset((c.entity_a.name, c.entity_b.name)): c.fixed_rotation for c in up.world.joints}
    fixed = [c for c in ours.world.joints if isinstance(c.fixed_rotation, torch.Tensor)]
    assert fixed, "waterfall has a joint that holds its ends' angles"
    for constraint in fixed:
        expected = held[frozenset((constraint.entity_a.name, constraint.entity_b.name))]
        assert torch.equal(constraint.fixed_rotation, expected)
    seen = parity.run_lockstep(up, ours, seed=0, steps=6, resync=True, actions=lambda g: space_actions(ours, g))
    assert seen.fastest > 0.1


def test_copy_random_stream_lines_up_observation_noise():
    """asym_joint draws which end is agent 0 once per env (VMAS once per batch), so after the reset the two
    random streams stand at different places; from VMAS's place, the noise of the next observation agrees."""
    up, ours = parity.make_vmas_env("asym_joint", 3), vmas_ros.make_env("asym_joint", num_envs=3)
    parity.copy_start(up, ours, vmas_states.asym_joint)
    actions = [torch.zeros(3, 2)] * 2
    unsynced = ours.step([a.clone() for a in actions])[0]
    expected = up.step([a.clone() for a in actions])[0]
    assert not torch.allclose(unsynced[0], expected[0], atol=parity.ATOL)

    up, ours = parity.make_vmas_env("asym_joint", 3), vmas_ros.make_env("asym_joint", num_envs=3)
    parity.copy_start(up, ours, vmas_states.asym_joint)
    parity.copy_random_stream(up, ours)
    synced = ours.step([a.clone() for a in actions])[0]
    expected = up.step([a.clone() for a in actions])[0]
    for mine, theirs in zip(synced, expected):
        torch.testing.assert_close(mine, theirs, atol=parity.ATOL, rtol=0)
