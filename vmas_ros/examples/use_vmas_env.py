"""Step a batched environment with random or fixed actions, optionally saving a video of env 0."""
import time

import torch

from vmas_ros import make_env
from vmas_ros.simulator.utils import save_video


def _fixed_action(agent, continuous: bool, env) -> torch.Tensor:
    """The same action in every env: half the agent's first control range (continuous) or action 3 (discrete)."""
    if continuous:
        action = torch.zeros(env.batch_dim, agent.action_size, device=env.device)
        action[:, 0] = 0.5 * float(torch.as_tensor(agent.u_range).reshape(-1)[0])
        return action
    return torch.full((env.batch_dim, 1), 3, device=env.device, dtype=torch.long)


def use_vmas_env(
    render: bool = False,
    save_render: bool = False,
    num_envs: int = 32,
    n_steps: int = 100,
    random_action: bool = False,
    device: str = "cpu",
    scenario_name: str = "waterfall",
    continuous_actions: bool = True,
    visualize_render: bool = True,
    dict_spaces: bool = True,
    **kwargs,
):
    """Run ``n_steps`` of ``scenario_name`` in ``num_envs`` envs; returns the number of steps taken.

    ``dict_spaces`` passes actions as a dict by agent name (else a list);
    ``save_render`` (needs ``render``) writes ``<scenario_name>`` as a video.
    """
    if save_render and not render:
        raise ValueError("save_render=True needs render=True: frames come from render()")
    env = make_env(scenario_name, num_envs=num_envs, device=device, continuous_actions=continuous_actions,
                   dict_spaces=dict_spaces, wrapper=None, seed=0, **kwargs)
    frames = []
    start = time.time()
    for _ in range(n_steps):
        acts = [env.get_random_action(a) if random_action else _fixed_action(a, continuous_actions, env)
                for a in env.agents]
        env.step({a.name: u for a, u in zip(env.agents, acts)} if dict_spaces else acts)
        if render:
            frame = env.render(mode="rgb_array", agent_index_focus=None, visualize_when_rgb=visualize_render)
            if save_render:
                frames.append(frame)
    print(f"{n_steps} steps of {num_envs} envs of {scenario_name!r} on {device} in {time.time() - start:.2f} s")
    if save_render:
        save_video(scenario_name, frames, fps=1 / env.scenario.world.dt)
    return n_steps


if __name__ == "__main__":
    use_vmas_env(scenario_name="waterfall", render=False, random_action=False)
