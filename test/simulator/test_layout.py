"""The planar layout: bit-exact conversions, and the physics state kept between steps is never stale."""
from __future__ import annotations

import pytest
import torch

import vmas_ros

from vmas_ros.simulator.layout import join_xy, split_xy, split_xy_into, split_xy_stacked

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
SPECIAL = [0.0, -0.0, 1e-45, -1e-45, 3.4e38, -3.4e38, float("inf"), float("-inf"), float("nan"), 1.0, -2.5]


def _bits(t: torch.Tensor) -> torch.Tensor:
    return t.contiguous().view(torch.int32)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_split_and_join_copy_bits_exactly(device, dtype):
    gen = torch.Generator().manual_seed(0)
    values = torch.cat([torch.tensor(SPECIAL), torch.randn(1001, generator=gen) * 1e3])
    vectors = torch.stack([values, values.flip(0)], dim=-1).reshape(2, -1, 2).to(device=device, dtype=dtype)
    x, y = split_xy(vectors)
    assert x.is_contiguous() and y.is_contiguous()
    stacked = split_xy_stacked(vectors)
    assert stacked.shape == (2, *vectors.shape[:-1])
    for got, want in ((x, vectors[..., 0]), (y, vectors[..., 1]), (stacked[0], vectors[..., 0]),
                      (stacked[1], vectors[..., 1])):
        assert got.dtype == dtype and got.device == vectors.device
        view = torch.int64 if dtype == torch.float64 else torch.int32
        assert torch.equal(got.contiguous().view(view), want.contiguous().view(view))  # NaN, -0 and subnormals too
    joined = join_xy(x, y)
    view = torch.int64 if dtype == torch.float64 else torch.int32
    assert joined.shape == vectors.shape and torch.equal(joined.view(view), vectors.view(view))


def test_split_of_a_non_contiguous_tensor_falls_back():
    vectors = torch.randn(3, 5, 4)[..., 1:3]
    x, y = split_xy(vectors)
    assert torch.equal(x, vectors[..., 0]) and torch.equal(y, vectors[..., 1])


@pytest.mark.parametrize("device", DEVICES)
def test_state_written_between_steps_is_seen_by_the_next_step(device):
    """The world keeps last step's planar state; in-place writes and replaced tensors must invalidate it."""
    def run(edit):
        env = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=3)
        env.reset()
        actions = [torch.full((4, 2), 0.3, device=device) for _ in env.agents]
        env.step(actions)
        edit(env)
        env.step(actions)
        return torch.stack([a.state.pos for a in env.agents])

    def in_place(env):
        env.agents[0].state.pos[:, 0] += 0.5
        env.agents[1].state.vel.mul_(0.0)
        env.agents[2].state.rot[:] = 1.0

    def replaced(env):
        env.agents[0].set_pos(env.agents[0].state.pos + torch.tensor([0.5, 0.0], device=device), batch_index=None)
        env.agents[1].set_vel(torch.zeros(4, 2, device=device), batch_index=None)

    untouched = run(lambda env: None)
    for edit in (in_place, replaced):
        moved = run(edit)
        # agent_0 was shifted by 0.5 in x before the second step (contacts aside, it ends ~0.5 further)
        assert (moved[0, :, 0] - untouched[0, :, 0]).abs().min() > 0.3
        assert not torch.allclose(moved[1], untouched[1])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_split_into_slots_copies_bits_exactly(device, dtype):
    gen = torch.Generator().manual_seed(1)
    values = torch.cat([torch.tensor(SPECIAL), torch.randn(501, generator=gen)])
    vectors = torch.stack([values, values.flip(0)], dim=-1).reshape(4, -1, 2).to(device=device, dtype=dtype)
    target = torch.full((3, 4, vectors.shape[1]), 7.0, device=device, dtype=dtype)
    split_xy_into(vectors, target[:2])
    view = torch.int64 if dtype == torch.float64 else torch.int32
    assert torch.equal(target[0].view(view), vectors[..., 0].contiguous().view(view))
    assert torch.equal(target[1].view(view), vectors[..., 1].contiguous().view(view))
    assert (target[2] == 7.0).all(), "only the two slots are written"
