"""Command-line handling of ``vmas-ros bench``: the options
(:func:`add_bench_arguments`, :func:`parse_bench_args`) and running them
(:func:`run_bench_command`).
It is the top of :mod:`vmas_ros.bench`: it imports the benchmarks, none
of them imports it.
"""
from __future__ import annotations

import argparse
import sys

from vmas_ros.bench.report import plot_available
from vmas_ros.bench.common import BENCHMARKS, DEFAULT_MODE_WARMUP_MAX_STEPS, DEFAULT_NUM_ENVS

__all__ = ["add_bench_arguments", "parse_bench_args", "run_bench_command"]


# ---------------------------------------------------------------------- CLI
def add_bench_arguments(parser: argparse.ArgumentParser, with_benchmark_name: bool = True) -> argparse.ArgumentParser:
    """Add the ``bench`` options to ``parser``. With ``with_benchmark_name`` a positional
    benchmark name (``mpe``, the default, or ``suite``) is added first, for
    ``vmas-ros bench mpe ...``; pass False when ``mpe`` is already a subcommand.
    Options marked "suite:" only apply to ``vmas-ros bench suite``."""
    if with_benchmark_name:
        parser.add_argument("benchmark", nargs="?", default="mpe",
                            help="which benchmark: mpe (default; the VMAS paper's Fig. 2), suite (vmas_ros "
                                 "against VMAS on the project's workloads), node (sim_node's steps/s while "
                                 "publishing), process (whole short scripts against VMAS: time and memory), "
                                 "jaxmarl (simple_spread's step against JaxMARL's), torchrl (TorchRL's "
                                 "multi-agent PPO loop at its tutorial's size, whole processes against VMAS) or "
                                 "randomisation (what training's randomisation costs navigation's step)")
    # dest is not ``num_envs``: cli.main compares args.num_envs with an int
    parser.add_argument("--num-envs", dest="bench_num_envs", type=int, nargs="+", default=list(DEFAULT_NUM_ENVS),
                        metavar="N", help="mpe: numbers of parallel envs (default: 1 10 100 1000)")
    parser.add_argument("--steps", type=int, default=100, help="steps per timed run (default 100, as the paper)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per side and num_envs (default 3)")
    parser.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs per side (default 1)")
    parser.add_argument("--devices", nargs="+", default=None, metavar="DEVICE",
                        help="torch devices for vmas_ros/VMAS (default: cpu, plus cuda if available)")
    parser.add_argument("--peers", nargs="*", default=None, metavar="PEER",
                        help="peers to compare with: vmas, mpe (default: those installed)")
    parser.add_argument("--mpe-max-envs", type=int, default=None, metavar="N",
                        help="step at most N MPE envs; above, extrapolate linearly (default: no cap)")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads for the run (default: torch's)")
    parser.add_argument("--out", default="bench_results", help="output folder (default bench_results/)")
    parser.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    suite = parser.add_argument_group("suite options (vmas-ros bench suite)")
    suite.add_argument("--workloads", nargs="+", default=None, metavar="NAME",
                       help="suite: workloads to run (default: all; an unknown name lists the valid ones)")
    suite.add_argument("--scale", type=float, default=1.0,
                       help="suite: multiply every env count by this, at least 1 env (default 1; e.g. 0.01)")
    suite.add_argument("--curve-envs", type=int, nargs="+", default=None, metavar="N",
                       help="suite: num_envs of scaling_envs, before --scale (default: 1 10 100 1000 10000 30000)")
    suite.add_argument("--curve-agents", type=int, nargs="+", default=None, metavar="N",
                       help="suite: sphere counts of scaling_agents, overlapping (default: 10 30 100 300 1000)")
    suite.add_argument("--curve-agents-sparse", type=int, nargs="+", default=None, metavar="N",
                       help="suite: sphere counts of scaling_agents_sparse, spread as a swarm "
                            "(default: 100 300 1000 3000 10000 30000 100000)")
    suite.add_argument("--max-peer-agents", type=int, default=None, metavar="N",
                       help="suite: run VMAS only at points of up to N agents (the agent curves, swarms, "
                            "navigation swarms); above, omitted (default 100)")
    # no argparse choices: a bad mode exits 2 with the suite's own message, like its other options
    suite.add_argument("--modes", nargs="+", default=None, metavar="MODE",
                       help="suite: how vmas_ros is stepped: default (as make_env builds it without flags, its long "
                            "run: the warm-up steps on through the default mode's switch to the compiled step when "
                            f"that comes within {DEFAULT_MODE_WARMUP_MAX_STEPS:,} steps), eager, compiled (physics "
                            "through torch.compile, compiled during the warm-up runs) or eager and compiled, "
                            "timed side by side (default: default; memory_30k is eager outside the default mode)")
    suite.add_argument("--compile-physics", action="store_true",
                       help="suite: the same as --modes compiled (kept for older commands)")
    process = parser.add_argument_group("process options (vmas-ros bench process)")
    process.add_argument("--process-workloads", nargs="+", default=None, metavar="SCENARIO_ENVS",
                         help="process: <scenario>_<num_envs> (default: transport_32 navigation_60)")
    process.add_argument("--process-steps", type=int, nargs="+", default=None, metavar="N",
                         help="process: steps per process (default: 100 1000 10000)")
    process.add_argument("--process-mode", default="default", metavar="MODE",
                         help="process: vmas_ros as make_env builds it without flags (default), or eager, "
                              "or compiled")
    process.add_argument("--process-cold-cache", action="store_true",
                         help="process: each vmas_ros process compiles from an empty compile cache of its own "
                              "(a machine's first compile); default: torch's cache as earlier runs left it")
    randomised = parser.add_argument_group("randomisation options (vmas-ros bench randomisation)")
    randomised.add_argument("--randomisation-envs", type=int, default=None, metavar="N",
                            help="randomisation: navigation's num_envs (default 600)")
    randomised.add_argument("--randomisation-modes", nargs="+", default=None, metavar="MODE",
                            help="randomisation: eager and/or compiled steps (default: both)")
    jaxmarl = parser.add_argument_group("jaxmarl options (vmas-ros bench jaxmarl)")
    jaxmarl.add_argument("--jaxmarl-python", default=None, metavar="PATH",
                         help="jaxmarl: the interpreter of an environment with JaxMARL installed "
                              "(default: $VMAS_ROS_JAXMARL_PYTHON)")
    jaxmarl.add_argument("--jaxmarl-envs", type=int, nargs="+", default=None, metavar="N",
                         help="jaxmarl: numbers of envs (default: 1 30000)")
    jaxmarl.add_argument("--jaxmarl-steps", type=int, default=None, metavar="N",
                         help="jaxmarl: timed steps per process (default 2000)")
    from vmas_ros.bench.node import add_node_bench_arguments

    add_node_bench_arguments(parser)
    return parser


def parse_bench_args(argv) -> argparse.Namespace:
    """The options ``vmas-ros bench <argv>`` runs with, e.g. ``["suite", "--workloads", "spread_1"]``."""
    parser = argparse.ArgumentParser(prog="vmas-ros bench")
    add_bench_arguments(parser)
    return parser.parse_args(argv)


def _report(name: str, module, run) -> int:
    """Run ``run()`` for ``vmas-ros bench NAME``, print ``module.format_table`` of its rows and write them with
    ``module.write_results`` to ``--out``: 0, or 2 with the message when ``run`` refuses its options."""
    try:
        rows, out = run()
    except ValueError as error:
        print(f"vmas-ros bench {name}: {error}", file=sys.stderr)
        return 2
    print(module.format_table(rows))
    for path in module.write_results(rows, out).values():
        print(f"wrote {path}")
    return 0


def _run_process(args: argparse.Namespace) -> int:
    """``vmas-ros bench process``: whole processes of vmas_ros and VMAS, alternating (:mod:`vmas_ros.bench.process`)."""
    from vmas_ros.bench import process

    return _report("process", process, lambda: (process.run_process_benchmark(
        args.process_workloads or process.DEFAULT_WORKLOADS, args.process_steps or process.DEFAULT_STEPS,
        args.repeats, mode=args.process_mode, threads=args.threads, progress=not args.no_progress,
        cold_cache=args.process_cold_cache), args.out))


def _run_jaxmarl(args: argparse.Namespace) -> int:
    """``vmas-ros bench jaxmarl``: simple_spread against JaxMARL, alternating processes
    (:mod:`vmas_ros.bench.jaxmarl_bench`)."""
    from vmas_ros.bench import jaxmarl_bench as jaxmarl

    return _report("jaxmarl", jaxmarl, lambda: (jaxmarl.run_jaxmarl_benchmark(
        jaxmarl.jaxmarl_python(args.jaxmarl_python), args.jaxmarl_envs or jaxmarl.DEFAULT_NUM_ENVS,
        args.jaxmarl_steps or jaxmarl.DEFAULT_STEPS, args.repeats, progress=not args.no_progress), args.out))


def _run_torchrl(args: argparse.Namespace) -> int:
    """``vmas-ros bench torchrl``: TorchRL's PPO loop on vmas_ros and on VMAS (:mod:`vmas_ros.bench.torchrl_loop`)."""
    from vmas_ros.bench import torchrl_loop

    return _report("torchrl", torchrl_loop,
                   lambda: (torchrl_loop.run_torchrl_benchmark(args.repeats, progress=not args.no_progress), args.out))


def _run_randomisation(args: argparse.Namespace) -> int:
    """``vmas-ros bench randomisation``: navigation's step with and without randomisation
    (:mod:`vmas_ros.bench.randomisation_bench`)."""
    from vmas_ros.bench import randomisation_bench as bench

    return _report("randomisation", bench, lambda: (bench.run_randomisation_benchmark(
        args.randomisation_envs or bench.DEFAULT_NUM_ENVS, args.steps, args.repeats,
        args.randomisation_modes or bench.MODES, progress=not args.no_progress), args.out))


def run_bench_command(args: argparse.Namespace) -> int:
    """Run the benchmark from parsed ``add_bench_arguments`` options: 0 on success, 2 on bad arguments."""
    # looked up on the module at call time, so patches of vmas_ros.bench.mpe apply
    from vmas_ros.bench import mpe

    benchmark = getattr(args, "benchmark", "mpe") or "mpe"
    if benchmark == "node":
        from vmas_ros.bench.node import run_node_bench_command

        return run_node_bench_command(args)
    if benchmark not in BENCHMARKS:
        print(f"vmas-ros bench: unknown benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}", file=sys.stderr)
        return 2
    if benchmark == "suite":
        from vmas_ros.bench.suite import run_suite_command

        return run_suite_command(args)
    if benchmark == "process":
        return _run_process(args)
    if benchmark == "jaxmarl":
        return _run_jaxmarl(args)
    if benchmark == "torchrl":
        return _run_torchrl(args)
    if benchmark == "randomisation":
        return _run_randomisation(args)
    num_envs = getattr(args, "bench_num_envs", None)
    if num_envs is None:
        num_envs = getattr(args, "num_envs", [1, 10, 100, 1000])
    if isinstance(num_envs, int):
        num_envs = [num_envs]
    options = dict(
        num_envs=list(num_envs), steps=args.steps, repeats=getattr(args, "repeats", 3),
        devices=getattr(args, "devices", None), peers=getattr(args, "peers", None),
        mpe_max_envs=getattr(args, "mpe_max_envs", None), threads=getattr(args, "threads", None),
        warmup=getattr(args, "warmup", 1),
    )
    try:
        mpe._validate(**options)
    except ValueError as error:
        print(f"vmas-ros bench: {error}", file=sys.stderr)
        return 2
    plot = plot_available(not getattr(args, "no_plot", False))
    rows = mpe.run_mpe_benchmark(progress=not getattr(args, "no_progress", False), **options)
    paths = mpe.write_results(rows, getattr(args, "out", "bench_results"), plot=plot)
    print(mpe.format_table(rows))
    print()
    for path in paths.values():
        print(f"wrote {path}")
    return 0
