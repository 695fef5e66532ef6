"""JaxMARL's side of ``vmas-ros bench jaxmarl``: simple_spread's step time in JaxMARL, as JSON on stdout.

Run by the interpreter of a separate environment that has JaxMARL (it pins
its own JAX), so this file imports nothing from vmas_ros:

    python jaxmarl_side.py '{"num_envs": 1, "steps": 2000, "warmup": 200, "seed": 0}'

The step is ``jax.jit(jax.vmap(env.step))``, called once per step from
Python, as a user's loop calls an env: continuous actions drawn beforehand
inside the action space's bounds, the state carried from step to step, and
one ``block_until_ready`` after the last step (JAX runs asynchronously).
"""
from __future__ import annotations

import json
import os
import sys
import time

# run as a script, its folder (vmas_ros/bench/) would come first on sys.path and shadow libraries by its
# modules' names: leave it out
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or os.curdir) != _HERE]


def main(config: dict) -> dict:
    import jax
    import jaxmarl

    num_envs, steps, warmup = config["num_envs"], config["steps"], config["warmup"]
    env = jaxmarl.make("MPE_simple_spread_v3", action_type="Continuous")
    key = jax.random.PRNGKey(config["seed"])
    key, reset_key, step_key = jax.random.split(key, 3)
    _, state = jax.vmap(env.reset)(jax.random.split(reset_key, num_envs))
    step = jax.jit(jax.vmap(env.step))
    step_keys = jax.random.split(step_key, num_envs)

    def draw(count: int, key) -> list:
        per_agent = {}
        for agent in env.agents:
            space = env.action_space(agent)
            key, sub = jax.random.split(key)
            per_agent[agent] = jax.random.uniform(sub, (count, num_envs, *space.shape), minval=space.low,
                                                  maxval=space.high)
        return [{agent: actions[i] for agent, actions in per_agent.items()} for i in range(count)]

    key, warm_key, timed_key = jax.random.split(key, 3)
    started = time.perf_counter()
    for actions in draw(warmup, warm_key):
        _, state, _, _, _ = step(step_keys, state, actions)
    jax.block_until_ready(state)
    warmup_s = time.perf_counter() - started
    timed = draw(steps, timed_key)
    jax.block_until_ready(timed)
    started = time.perf_counter()
    for actions in timed:
        _, state, _, _, _ = step(step_keys, state, actions)
    jax.block_until_ready(state)
    seconds = time.perf_counter() - started
    return {"side": "JaxMARL", "version": getattr(jaxmarl, "__version__", "?"), "jax": jax.__version__,
            "num_envs": num_envs, "steps": steps, "ms_per_step": 1000 * seconds / steps, "warmup_s": warmup_s}


if __name__ == "__main__":
    print(json.dumps(main(json.loads(sys.argv[1]))))
