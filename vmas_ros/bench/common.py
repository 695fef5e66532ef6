"""Names shared by the MPE benchmark (:mod:`vmas_ros.bench.mpe`) and its report
(:mod:`vmas_ros.bench.report`): the scenario, the sides, their labels and the
CSV columns. Re-exported by :mod:`vmas_ros.bench.mpe`. ``BENCHMARKS`` also names
the suite (:mod:`vmas_ros.bench.suite`) and the node benchmark (:mod:`vmas_ros.bench.node`);
``COMPILED_SIDE`` is the suite's extra, compiled vmas_ros side.
"""
from __future__ import annotations

SCENARIO = "simple_spread"
N_AGENTS = 3
SIDES = ("vmas_ros", "vmas", "mpe")
PEERS = ("vmas", "mpe")
_PEER_MODULE = {"vmas": "vmas", "mpe": "mpe2"}
_PEER_INSTALL = {"vmas": "pip install vmas==1.5.2", "mpe": "pip install mpe2"}
#: the suite's (:mod:`vmas_ros.bench.suite`) vmas_ros side with its physics through torch.compile, measured
#: next to the eager "vmas_ros" side by ``--modes eager compiled``; not one of SIDES (bench mpe has no such side)
COMPILED_SIDE = "vmas_ros_compiled"
_LABEL = {"vmas_ros": "vmas_ros", "vmas": "VMAS", "mpe": "MPE", COMPILED_SIDE: "vmas_ros compiled"}
BENCHMARKS = ("mpe", "suite", "node", "process", "jaxmarl", "torchrl", "randomisation")
#: The default mode's long run, as the benchmarks time it: a warm-up steps on through the default mode's
#: switch to the compiled step when that comes within this many steps; a later switch is timed eager
DEFAULT_MODE_WARMUP_MAX_STEPS = 20_000
#: bench mpe's default ``--num-envs``; the suite refuses any other value (it takes ``--scale``)
DEFAULT_NUM_ENVS = [1, 10, 100, 1000]

CSV_COLUMNS = [
    "run_id", "scenario", "side", "device", "num_envs", "steps", "repeats", "median_s", "min_s", "max_s",
    "per_step_ms", "env_steps_per_s", "extrapolated", "measured_envs", "measured_in_round", "threads",
    "times_s", "peak_rss_mb", "torch_peak_mb", "loadavg_1m",
]
