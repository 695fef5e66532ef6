"""Shared pieces of the parity tests against upstream VMAS (the oracle).

Every parity test does the same three things: write one random initial state
into both worlds, step both with identical actions, and require the same
states. These helpers are the first and the last step.
"""
from __future__ import annotations

import torch

FIELDS = ("pos", "vel", "rot", "ang_vel")
ATOL = 1e-4


def copy_random_state(up, ours, seed: int, spread: float, agents_only: bool = False) -> None:
    """Write one random (contact-rich when ``spread`` is small) state into both worlds."""
    gen = torch.Generator().manual_seed(seed)
    batch = up.world.batch_dim
    pairs = zip(up.world.agents, ours.world.agents) if agents_only else zip(up.world.entities, ours.world.entities)
    for e_up, e_ours in pairs:
        values = {
            "pos": (torch.rand(batch, 2, generator=gen) * 2 - 1) * spread,
            "vel": (torch.rand(batch, 2, generator=gen) * 2 - 1) * 0.3,
            "rot": (torch.rand(batch, 1, generator=gen) * 2 - 1) * 3.0,
            "ang_vel": (torch.rand(batch, 1, generator=gen) * 2 - 1) * 0.5,
        }
        for field, value in values.items():
            getattr(e_up, f"set_{field}")(value.to(up.device), batch_index=None)
            getattr(e_ours, f"set_{field}")(value.to(ours.device), batch_index=None)


def assert_same_state(up, ours, step: int) -> None:
    """Positions within 1e-4; velocities and angles 1e-4 absolute plus 1e-4 relative."""
    assert [e.name for e in up.world.entities] == [e.name for e in ours.world.entities]
    for e_up, e_ours in zip(up.world.entities, ours.world.entities):
        for field in FIELDS:
            expected, actual = getattr(e_up.state, field), getattr(e_ours.state, field)
            assert actual.device == expected.device
            assert torch.isfinite(actual).all(), f"{e_ours.name}.{field} not finite at step {step}"
            # derivatives may carry float32 rounding relative to their size
            torch.testing.assert_close(
                actual, expected, atol=ATOL, rtol=0 if field == "pos" else 1e-4,
                msg=lambda m: f"step {step}, {e_ours.name}.{field}: {m}",
            )
