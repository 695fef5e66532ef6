"""sim_node's learning interface: observations, rewards and raw actions as ROS topics, and a policy inside.

External policies (a ``policy_node``, a training process, a script) see what a
learner sees through the Environment API, for the published env ``env_index``:

publishes  ``<agent>/observation`` (std_msgs/Float32MultiArray: the agent's
           observation vector, one layout dim labelled ``observation``) and
           ``<agent>/reward`` (std_msgs/Float32: its reward of the last step);
subscribes ``<agent>/action`` (std_msgs/Float32MultiArray: the raw action
           vector as ``Environment.step`` takes it, clamped to the action range).

The node steps at up to hundreds of Hz with many agents, so the conversion is
done in bulk: every agent's observation and reward of ``env_index`` is gathered
into one tensor, copied to the host once per step, and written in place into
message objects created once. Received actions are validated on arrival (size,
NaN/inf) and applied once per step like a ``cmd_vel``.

``control: policy`` runs an exported policy (``vmas_ros.policy.onnx_policy``)
on all envs at once for every agent without a live command; ``load_policy``
refuses a policy whose metadata does not fit the running scenario.
"""
from __future__ import annotations

import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from std_msgs.msg import Float32, Float32MultiArray, MultiArrayDimension

from vmas_ros.ros.lifecycle import SimulationFault
from vmas_ros.ros.topic_audit import quiet_publisher_events, quiet_subscription_events

#: seconds between two warnings about dropped actions (a broken publisher floods)
WARN_PERIOD = 2.0
#: seconds between checks whether the observation and reward topics have subscribers (see AgentTopics._listened)
LISTENERS_RECHECK_S = 0.01


def flat_observation(obs) -> torch.Tensor:
    """One agent's observation as [num_envs, n] (a dict observation: its values concatenated in key order)."""
    if isinstance(obs, dict):
        return torch.cat([flat_observation(obs[key]) for key in sorted(obs)], dim=1)
    return obs.reshape(obs.shape[0], -1)


def action_bounds(env) -> List[Tuple[torch.Tensor, torch.Tensor]]:
    """Per agent, the inclusive (low, high) of its action vector on the env's device."""
    bounds = []
    for agent in env.agents:
        space = env.get_agent_action_space(agent)
        low = torch.as_tensor(np.asarray(space.low, dtype=np.float32), device=env.device)
        high = torch.as_tensor(np.asarray(space.high, dtype=np.float32), device=env.device)
        bounds.append((low, high))
    return bounds


class AgentTopics:
    """Observation/reward publishers and action subscribers of every agent, with the latest actions.

    ``send(publisher, message)`` is the node's publish function (it also records
    to the bag). Actions are kept as host arrays with their arrival time; the
    node's step reads them through ``apply``.
    """

    def __init__(self, node, env, agent_names: Sequence[str], pub_qos, sub_qos,
                 send: Callable, on_action: Optional[Callable] = None, topics: bool = True) -> None:
        """``topics``: False makes no topics at all (a swarm without per-agent topics); the action
        bounds are still there for the node's own policy."""
        self.node, self.env, self.names = node, env, list(agent_names) if topics else []
        self.send = send
        self.on_action = on_action  # e.g. record the received message
        self.sizes = [env.get_agent_action_size(a) for a in env.agents]
        self.bounds = action_bounds(env)
        quiet = quiet_publisher_events  # no per-round event handlers (see topic_audit.quiet_publisher_events)
        self.obs_pubs = [node.create_publisher(Float32MultiArray, f"{n}/observation", pub_qos, event_callbacks=quiet())
                         for n in self.names]
        self.reward_pubs = [node.create_publisher(Float32, f"{n}/reward", pub_qos, event_callbacks=quiet())
                            for n in self.names]
        self.obs_msgs: List[Float32MultiArray] = []
        self.obs_views: List[np.ndarray] = []  # numpy views on each message's array.array (written in place)
        self.reward_msgs = [Float32() for _ in self.names]
        self.actions: Dict[int, Tuple[np.ndarray, float]] = {}  # agent index -> (action, monotonic arrival)
        self._warned: Dict[int, float] = {}  # agent index -> last warning (throttled per agent)
        self._listeners_checked, self._any_listener = float("-inf"), False  # see _listened
        self.action_subs = [
            node.create_subscription(Float32MultiArray, f"{name}/action", lambda msg, i=i: self._on_action(i, msg), sub_qos,
                                     event_callbacks=quiet_subscription_events())
            for i, name in enumerate(self.names)
        ]

    # ------------------------------------------------------------ publishing
    def _shape(self, sizes: List[int]) -> None:
        """(Re)build the observation messages for these sizes: once, unless a scenario changes them."""
        self.obs_msgs, self.obs_views = [], []
        for size in sizes:
            msg = Float32MultiArray()
            msg.layout.dim = [MultiArrayDimension(label="observation", size=size, stride=size)]
            msg.layout.data_offset = 0
            msg.data = np.zeros(size, dtype=np.float32).tolist() if size else []
            self.obs_msgs.append(msg)
            self.obs_views.append(np.frombuffer(msg.data, dtype=np.float32) if size else np.zeros(0, np.float32))

    def publish(self, obs: Sequence, rewards: Optional[Sequence], env_index: int, always: bool = False) -> None:
        """Publish env ``env_index``'s observations (and rewards, after the first step) with one host copy.

        Skipped while nobody subscribes (most runs have no learner attached),
        unless ``always`` (the node records every topic to a bag).
        """
        if not self.names or (not always and not self._listened()):
            return
        rows = [flat_observation(o)[env_index] for o in obs]
        sizes = [int(r.numel()) for r in rows]
        parts = rows + ([r[env_index].reshape(1).float() for r in rewards] if rewards is not None else [])
        with torch.no_grad():
            host = torch.cat([p.float() for p in parts]).cpu().numpy()
        if np.isnan(host).any():  # checked before any of them is sent: no NaN leaves the node
            raise SimulationFault(f"NaN in the observations or rewards of env {env_index}: {self._nan_names(host, sizes)}")
        if sizes != [v.size for v in self.obs_views]:
            self._shape(sizes)
        offset = 0
        for i, size in enumerate(sizes):
            self.obs_views[i][:] = host[offset:offset + size]
            offset += size
            self.send(self.obs_pubs[i], self.obs_msgs[i])
        if rewards is not None:
            for i, msg in enumerate(self.reward_msgs):
                msg.data = float(host[offset + i])
                self.send(self.reward_pubs[i], msg)

    def _listened(self) -> bool:
        """Whether anyone subscribes to an observation or reward topic, asked at most every
        ``LISTENERS_RECHECK_S`` (8 counts each step cost more than the rest of this publishing)."""
        now = time.monotonic()
        if now - self._listeners_checked >= LISTENERS_RECHECK_S:
            self._listeners_checked = now
            self._any_listener = any(p.get_subscription_count() for p in (*self.obs_pubs, *self.reward_pubs))
        return self._any_listener

    def _nan_names(self, host: np.ndarray, sizes: List[int]) -> str:
        """Which of the gathered vectors (observations, then rewards) hold NaN."""
        names, offset = [], 0
        for name, size in [(f"{n}/observation", s) for n, s in zip(self.names, sizes)] + \
                [(f"{n}/reward", 1) for n in self.names]:
            if offset < host.size and np.isnan(host[offset:offset + size]).any():
                names.append(name)
            offset += size
        return ", ".join(names)

    # -------------------------------------------------------------- actions
    def _on_action(self, index: int, msg: Float32MultiArray) -> None:
        values = np.frombuffer(msg.data, dtype=np.float32) if len(msg.data) else np.zeros(0, np.float32)
        expected = self.sizes[index]
        if values.size != expected or not np.isfinite(values).all():
            self._warn(index, expected, values)
            return
        self.actions[index] = (values.copy(), time.monotonic())
        if self.on_action is not None:
            self.on_action(index, msg)

    def _warn(self, index: int, expected: int, values: np.ndarray) -> None:
        now = time.monotonic()
        if now - self._warned.get(index, 0.0) < WARN_PERIOD:
            return
        self._warned[index] = now
        why = f"{values.size} values" if values.size != expected else "NaN or inf"
        shown = ", ".join(f"{v:g}" for v in values[:8]) + (", ..." if values.size > 8 else "")
        self.node.get_logger().warning(
            f"dropped an action for {self.names[index]} on {self.action_subs[index].topic_name}: "
            f"expected {expected} finite values, got {why} ([{shown}])"
        )

    def clear(self) -> None:
        self.actions.clear()

    def apply(self, actions: List[torch.Tensor], env_index: int, timeout: float,
              commands: Dict[int, tuple]) -> List[torch.Tensor]:
        """Write every live action into row ``env_index`` (a newer cmd_vel for the same agent wins).

        Stale actions (older than ``timeout`` s) are forgotten, so the fallback
        control drives that agent again. Values are clamped to the action range.
        """
        if not self.actions:
            return actions
        now = time.monotonic()
        for i, entry in list(self.actions.items()):
            values, received = entry
            if now - received > timeout:
                if self.actions.get(i) is entry:
                    del self.actions[i]
                continue
            command = commands.get(i)
            if command is not None and command[-1] > received:
                continue
            low, high = self.bounds[i]
            row = torch.as_tensor(values, device=low.device)
            actions[i] = actions[i].clone()
            actions[i][env_index] = torch.maximum(torch.minimum(row, high), low)
        return actions


# ------------------------------------------------------------------ the policy
def load_policy(path: str, env, agent_names: Sequence[str]):
    """The exported policy at ``path``, checked against the running scenario.

    Raises ValueError with the reason when it cannot be read or does not fit
    (agent names, observation or action sizes, action type): a mismatched
    policy would otherwise fail at the first step or, worse, act on the wrong
    vector without complaint.
    """
    from vmas_ros.policy.onnx_policy import OnnxPolicy

    try:
        policy = OnnxPolicy.load(path)
    except Exception as error:  # the loader's errors vary (JSON, ONNX, checksum): all mean "unusable"
        raise ValueError(f"cannot load policy {path!r}: {type(error).__name__}: {error}") from None
    problems = check_policy(policy, env, agent_names)
    if problems:
        raise ValueError(f"policy {path!r} does not fit scenario: " + "; ".join(problems))
    return policy


def check_policy(policy, env, agent_names: Sequence[str]) -> List[str]:
    """What does not match between a policy's metadata and the env (empty: it fits)."""
    problems = []
    raw = [a.name for a in env.agents]
    agents = list(getattr(policy, "agents", []) or [])
    if agents not in (raw, list(agent_names)):
        problems.append(f"agents {agents} != the scenario's {raw}")
    obs = env.get_from_scenario(get_observations=True, get_rewards=False, get_infos=False, get_dones=False)[0]
    obs_sizes = sorted({flat_observation(o).shape[1] for o in obs})
    if obs_sizes != [policy.observation_size]:
        problems.append(f"observation_size {policy.observation_size} != the scenario's {obs_sizes}")
    act_sizes = sorted({env.get_agent_action_size(a) for a in env.agents})
    if act_sizes != [policy.action_size]:
        problems.append(f"action_size {policy.action_size} != the scenario's {act_sizes}")
    action_type = getattr(policy, "action_type", None) or getattr(policy, "metadata", {}).get("action_type")
    if action_type != "continuous" or not env.continuous_actions:
        problems.append(f"action_type {action_type!r}: sim_node runs continuous actions")
    return problems


def start_policy(logger, params, env, agent_names: Sequence[str]):
    """The policy of sim_node's ``policy_path`` (None when unset), checked, with warnings logged."""
    if not params.policy_path:
        return None
    policy = load_policy(params.policy_path, env, agent_names)
    for note in policy_warnings(policy, params.scenario.removesuffix(".py"), params.kwargs()):
        logger.warning(note)
    logger.info(f"policy {params.policy_path} loaded for {len(agent_names)} agents")
    return policy


def policy_warnings(policy, scenario: str, kwargs: dict) -> List[str]:
    """Differences worth a warning but not a refusal (a renamed port of the same task still fits)."""
    notes = []
    if getattr(policy, "scenario", scenario) != scenario:
        notes.append(f"the policy was trained on scenario {policy.scenario!r}, running {scenario!r}")
    trained = getattr(policy, "scenario_kwargs", None) or getattr(policy, "metadata", {}).get("scenario_kwargs")
    if trained is not None and dict(trained) != dict(kwargs):
        notes.append(f"the policy was trained with scenario_kwargs {trained}, running {kwargs}")
    return notes


def _nan_where(values: torch.Tensor) -> str:
    """Which agents got NaN in how many envs, e.g. "for agent 1 in 3 of 4 envs" ([B, A, ...] values)."""
    bad = torch.isnan(values.reshape(values.shape[0], values.shape[1], -1)).any(dim=2)  # [B, A]
    agents = [str(i) for i in torch.nonzero(bad.any(dim=0)).flatten().tolist()]
    return f"for agent(s) {', '.join(agents)} in {int(bad.any(dim=1).sum())} of {values.shape[0]} envs"


def policy_actions(policy, obs: Sequence, bounds: List[Tuple[torch.Tensor, torch.Tensor]]) -> List[torch.Tensor]:
    """Actions of every agent in every env from one batched policy call, clamped to the action range."""
    with torch.no_grad():
        batch = torch.stack([flat_observation(o) for o in obs], dim=1).float()  # [B, A, obs]
        device = batch.device
        out = policy.act(np.ascontiguousarray(batch.cpu().numpy()))  # [B, A, act]
        actions = torch.as_tensor(np.asarray(out, dtype=np.float32), device=device)
        if torch.isnan(actions).any():  # a broken policy: stop rather than act on made-up values
            raise SimulationFault(f"the policy returned NaN actions {_nan_where(actions)}")
        lows = torch.stack([b[0] for b in bounds]).unsqueeze(0)
        highs = torch.stack([b[1] for b in bounds]).unsqueeze(0)
        actions = torch.maximum(torch.minimum(actions, highs), lows)
        return list(actions.unbind(1))
