"""An environment's own random streams: torch's (and CUDA's), numpy's and Python's.

Each ``Environment`` keeps the state of the three global generators as its
own and installs it only while its scenario code runs, then gives the
caller's back. So two envs built with the same seed replay each other
exactly, and other code drawing from the global generators (a training
loop's own sampling, another env) neither disturbs them nor is disturbed.
"""
from __future__ import annotations

import contextlib
import random
from typing import List, Optional

import numpy as np
import torch

__all__ = ["OwnRandomStreams"]


class OwnRandomStreams:
    """Mixin of ``Environment``: the env's random streams in ``_rng_state`` (needs ``self.device``)."""

    _rng_state: Optional[dict] = None
    #: the seed the streams were last seeded with (what other streams of the env start from)
    seed_given: int = 0

    def _seed_rng(self, seed: int) -> None:
        self.seed_given = seed
        with torch.random.fork_rng(devices=self._cuda_devices()):
            torch.manual_seed(seed)
            self._rng_state = self._capture_rng()
        self._rng_state["numpy"] = np.random.RandomState(seed).get_state()
        self._rng_state["python"] = random.Random(seed).getstate()

    def _cuda_devices(self) -> list:
        return [self.device] if self.device.type == "cuda" else []

    def _capture_rng(self) -> dict:
        state = {"torch": torch.random.get_rng_state()}
        if self.device.type == "cuda":
            state["cuda"] = torch.cuda.get_rng_state(self.device)
        return state

    @contextlib.contextmanager
    def _own_rng(self):
        """Run scenario code with this env's RNG streams (torch, numpy, Python), then restore the caller's.

        Swapping numpy's and Python's global states costs more than a whole
        step at small batch sizes, so ``step`` swaps only torch's streams (where
        scenarios draw noise; :meth:`_swap_torch_rng`); construction, resets,
        random actions and queries swap all three (where scenarios place entities).
        """
        callers = self._swap_torch_rng(None)
        saved_np, saved_py = np.random.get_state(), random.getstate()
        np.random.set_state(self._rng_state["numpy"])
        random.setstate(self._rng_state["python"])
        try:
            yield
        finally:
            host = np.random.get_state(), random.getstate()
            np.random.set_state(saved_np)
            random.setstate(saved_py)
            self._swap_torch_rng(callers)
            self._rng_state["numpy"], self._rng_state["python"] = host

    def _swap_torch_rng(self, callers):
        """Swap torch's streams: given None, save the caller's and install this env's (returns the caller's);
        given the caller's, keep this env's as they are now and restore the caller's.

        Straight on the default generator, without a dict, on the CPU: a step does this twice, and at one
        env the wrappers cost as much as the copies of the generator's state.
        """
        generator = torch.default_generator
        own = self._rng_state
        if "cuda" in own:
            return self._swap_with_cuda(callers)
        if callers is None:
            callers = generator.get_state()
            generator.set_state(own["torch"])
            return callers
        own["torch"] = generator.get_state()
        generator.set_state(callers)
        return None

    def _swap_with_cuda(self, callers: Optional[dict]) -> Optional[dict]:
        """:meth:`_swap_torch_rng` for an env on a CUDA device: its CPU and CUDA streams both."""
        own = self._rng_state
        if callers is None:
            callers = self._capture_rng()
            torch.random.set_rng_state(own["torch"])
            torch.cuda.set_rng_state(own["cuda"], self.device)
            return callers
        own.update(self._capture_rng())
        torch.random.set_rng_state(callers["torch"])
        torch.cuda.set_rng_state(callers["cuda"], self.device)
        return None

    def seed(self, seed: Optional[int] = None) -> List[int]:
        """Re-seed this env's own random streams (torch, numpy, random)."""
        seed = 0 if seed is None else int(seed)
        self._seed_rng(seed)
        randomiser = getattr(self, "randomiser", None)  # randomisation draws from a stream of its own
        if randomiser is not None:
            randomiser.seed(seed)
        return [seed]

