"""Collect training batches on a Ray cluster with TorchRL's ``RayCollector``.

Each of ``collectors`` Ray actors holds a TorchRL ``Collector`` around one
batched env of ``num_envs / collectors`` envs and a copy of the policy. Every
iteration the learner (this process) asks all of them for a batch at once
(TorchRL's synchronous mode), joins the ``[collectors, envs_each, T]`` result
into ``[num_envs, T]`` and, after its update, sends them the new weights. The
frames per batch and the update are those of a single-process run; only who
steps the envs changes.

Actors are spread over the cluster's nodes (Ray's ``SPREAD`` strategy) and are
never restarted: a collector whose node dies ends the run with
:class:`CollectorLost`, which names the node, and the trainer's last checkpoint
continues it (``vmas-ros train --resume``).
"""
from __future__ import annotations

import os
import time
import warnings
from functools import partial
from typing import Any, Dict, List, Tuple

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.collectors import Collector

from vmas_ros.train.collection import SEED_STRIDE, Collection, EpisodeReturns

__all__ = ["RayCollection", "CollectorLost", "connect", "LOCAL", "NONE"]

#: ``--ray-address`` value: no Ray, collect in this process
NONE = "none"
#: ``--ray-address`` value: start a Ray instance on this machine, on 127.0.0.1
LOCAL = "local"
#: how long to wait for free CPUs before refusing to start the collectors
ROOM_WAIT_S = 10.0
#: how long to wait for the cluster to mark a failed collector's node dead before naming only the actor
NODE_DEATH_WAIT_S = 20.0
#: environment variables a collector inherits from the learner, so both build the same env
_FORWARDED_ENV = ("VMAS_ROS_COMPILE",)


class CollectorLost(RuntimeError):
    """A collector (or its node) died mid-run; the message names the node(s)."""


def connect(address: str) -> bool:
    """Connect this process to Ray; returns True if it started or joined a Ray runtime here.

    ``address`` is ``local`` (a Ray instance of this machine, every node on
    127.0.0.1), ``auto`` (the cluster ``ray start`` made on this machine, or
    ``RAY_ADDRESS``), or a head's ``host:port`` / ``ray://host:port``. Usage
    reporting to Ray's servers is off unless the user turned it on.
    """
    import ray

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if ray.is_initialized():
        return False
    if address == LOCAL:
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        ray.init(address="local", include_dashboard=False, log_to_driver=True, logging_level="warning")
    else:
        ray.init(address=address, log_to_driver=True, logging_level="warning")
    return True


def _make_torchrl_env(env_kwargs: Dict[str, Any]):
    """Build a collector's env (module level, so Ray ships it by reference)."""
    from vmas_ros.envs.make_env import make_env
    from vmas_ros.envs.torchrl_env import TorchRLEnv

    return TorchRLEnv(make_env(**env_kwargs))


def _check_room(collectors: int, cpus: int, gpus: bool) -> None:
    """Refuse a request the cluster cannot place now: Ray would wait for room forever."""
    import ray

    wanted = {"CPU": collectors * cpus, **({"GPU": collectors} if gpus else {})}
    deadline = time.monotonic() + ROOM_WAIT_S
    while True:  # actors that just stopped give their CPUs back a moment later
        free, total = ray.available_resources(), ray.cluster_resources()
        room = all(free.get(name, 0) >= needed for name, needed in wanted.items())
        never = any(total.get(name, 0) < needed for name, needed in wanted.items())
        if room or never or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    for resource, needed in wanted.items():
        if free.get(resource, 0) < needed:
            each = needed // collectors
            raise ValueError(f"{collectors} collectors x {each} {resource} need {needed} {resource}s; the Ray "
                             f"cluster has {free.get(resource, 0):g} free of {total.get(resource, 0):g}: "
                             f"use fewer collectors (--collectors) or CPUs each (--collector-cpus)")


def _failed_actor(error: BaseException):
    """The hex ID of the actor a Ray error is about, if it says."""
    actor_id = getattr(error, "actor_id", None) or getattr(error, "_actor_id", None)
    return actor_id.hex() if hasattr(actor_id, "hex") and not isinstance(actor_id, str) else actor_id


class _NodeCollector(Collector):
    """TorchRL's single-process collector that also says where it runs and how fast it steps."""

    def __init__(self, *args: Any, rng_seed: int = 0, threads: int = 1, **kwargs: Any) -> None:
        torch.set_num_threads(threads)
        self._timed_frames, self._timed_seconds = 0, 0.0
        torch.manual_seed(rng_seed)  # else every actor samples the same exploration noise
        super().__init__(*args, **kwargs)

    def print_remote_collector_info(self) -> None:
        """RayCollector calls this after start-up; ``where()`` gives the same facts to the caller."""

    def where(self) -> Dict[str, Any]:
        import ray

        context = ray.get_runtime_context()
        return {"node_id": context.get_node_id(), "node_ip": ray.util.get_node_ip_address(), "pid": os.getpid()}

    def rollout(self) -> TensorDictBase:
        start = time.perf_counter()
        batch = super().rollout()
        self._timed_seconds += time.perf_counter() - start
        self._timed_frames += batch.numel()
        return batch

    def load_weights(self, weights: TensorDictBase) -> None:
        """Copy the learner's policy weights (a TensorDict of the policy's parameters and buffers)."""
        weights.to(self.policy_device or "cpu").to_module(self.policy)

    def collection_stats(self) -> Dict[str, float]:
        return {"frames": self._timed_frames, "collect_seconds": self._timed_seconds}

    def __repr__(self) -> str:
        # Ray names the actor's log lines with this; Collector's own repr spans dozens of lines
        return f"{type(self).__name__}(envs={self.env.batch_size[0] if hasattr(self, 'env') else '?'})"


class RayCollection(Collection):
    """``collectors`` Ray actors stepping ``num_envs / collectors`` envs each (see the module docstring).

    Args:
        env_kwargs: :func:`vmas_ros.make_env` keyword arguments of the whole run
            (``num_envs`` is split between the collectors, ``seed`` is offset per collector).
        policy: the learner's stochastic policy; its weights are copied to every collector.
        steps: steps per batch (each collector's envs take this many).
        collectors: how many actors.
        cpus: CPUs each actor reserves (and torch threads it uses).
        device: torch device of the collectors' envs and policy copies.
        learner_device: where the joined batch goes.
        address: what was given to :func:`connect` (recorded in :meth:`describe`).
    """

    def __init__(self, env_kwargs: Dict[str, Any], policy, steps: int, collectors: int, cpus: int,
                 device: str, learner_device: torch.device, address: str) -> None:
        from torchrl.collectors.distributed import RayCollector

        num_envs = env_kwargs["num_envs"]
        if num_envs % collectors:
            raise ValueError(f"num_envs ({num_envs}) must be a multiple of collectors ({collectors}): "
                             f"each collector steps the same number of envs")
        each = num_envs // collectors
        _check_room(collectors, cpus, torch.device(device).type == "cuda")
        self.address, self.learner_device, self.steps, self.each = address, learner_device, steps, each
        makers, kwargs = [], []
        for k in range(collectors):
            makers.append(partial(_make_torchrl_env, {**env_kwargs, "num_envs": each, "device": device,
                                                      "seed": env_kwargs["seed"] + k * SEED_STRIDE}))
            kwargs.append({"rng_seed": env_kwargs["seed"] + k * SEED_STRIDE, "threads": cpus,
                           "auto_register_policy_transforms": False})
        forwarded = {name: os.environ[name] for name in _FORWARDED_ENV if name in os.environ}
        remote = {"num_cpus": cpus, "scheduling_strategy": "SPREAD", "max_restarts": 0,
                  "runtime_env": {"env_vars": {"RL_LOGGING_LEVEL": "WARNING", **forwarded}}}
        if torch.device(device).type == "cuda":
            remote["num_gpus"] = 1
        self.policy = policy
        # weight_sync_schemes={}: the learner ships weights through Ray's object store itself
        # (policy_updated); TorchRL's default Ray scheme opens a torch.distributed process group
        # between the learner and every collector, which needs more ports open between the nodes
        self._collector = RayCollector(
            makers, policy, frames_per_batch=each * steps * collectors, total_frames=2**62,
            collector_class=_NodeCollector, collector_kwargs=kwargs, sync=True, num_collectors=collectors,
            remote_configs=remote, device=device, weight_sync_schemes={})
        self._iterator = iter(self._collector)
        self.returns = EpisodeReturns(num_envs, learner_device)
        self.placement: List[Dict[str, Any]] = self._call("where")

    def _call(self, method: str) -> List[Any]:
        import ray

        try:
            return self._collector.map_fn(method)
        except ray.exceptions.RayError as error:
            raise self._lost(error) from error

    def _lost(self, error: BaseException) -> CollectorLost:
        """Name the collector(s) that failed and their node, and say whether the node left the cluster."""
        import ray

        failed = _failed_actor(error)
        placement = getattr(self, "placement", [])
        ids = [actor._actor_id.hex() for actor in getattr(self._collector, "remote_collectors", [])]
        suspects = [k for k, actor_id in enumerate(ids) if actor_id == failed] or list(range(len(placement)))
        # the cluster notices a dead node a little after its actors' connections drop
        deadline = time.monotonic() + NODE_DEATH_WAIT_S
        while True:
            alive = {node["NodeID"] for node in ray.nodes() if node.get("Alive")}
            gone = [k for k in suspects if k < len(placement) and placement[k]["node_id"] not in alive]
            if gone or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        if gone:
            names = ", ".join(f"collector {k} on node {placement[k]['node_id']} ({placement[k]['node_ip']})"
                              for k in gone)
            return CollectorLost(f"lost {names}: the node left the Ray cluster")
        where = ", ".join(f"collector {k} on node {placement[k]['node_id']} ({placement[k]['node_ip']})"
                          for k in suspects if k < len(placement))
        return CollectorLost(f"{where or 'a collector'} failed: {type(error).__name__}: "
                             f"{str(error).splitlines()[0] if str(error) else ''}")

    def collect(self) -> Tuple[TensorDictBase, torch.Tensor]:
        import ray

        try:
            with warnings.catch_warnings():
                # RayCollector expects one of its weight sync schemes; policy_updated does that job
                warnings.filterwarnings("ignore", message="RayCollector iteration started before weight")
                batch = next(self._iterator)
        except ray.exceptions.RayError as error:
            raise self._lost(error) from error
        batch = batch.exclude("collector").reshape(-1, self.steps).to(self.learner_device)
        return batch, self.returns.update(batch)

    def policy_updated(self) -> None:
        import ray

        weights = ray.put(TensorDict.from_module(self.policy).data.cpu())
        try:
            ray.get([actor.load_weights.remote(weights) for actor in self._collector.remote_collectors])
        except ray.exceptions.RayError as error:
            raise self._lost(error) from error

    def describe(self) -> Dict[str, Any]:
        stats = self._call("collection_stats")
        rows = []
        for k, (where, stat) in enumerate(zip(self.placement, stats)):
            seconds = stat["collect_seconds"]
            rows.append({"index": k, **where, "num_envs": self.each, "frames": stat["frames"],
                         "collect_seconds": round(seconds, 4),
                         "frames_per_second": round(stat["frames"] / seconds, 1) if seconds else None})
        return {"ray_address": self.address, "collectors": rows}

    def close(self) -> None:
        collector, self._collector = getattr(self, "_collector", None), None
        if collector is not None:
            collector.shutdown(shutdown_ray=False)

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass
