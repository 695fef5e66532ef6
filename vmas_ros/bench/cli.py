"""Command-line handling of ``vmas-ros bench``: the options
(:func:`add_bench_arguments`) and running them (:func:`run_bench_command`).
Both are re-exported by :mod:`vmas_ros.bench.mpe`.
"""
from __future__ import annotations

import argparse
import sys

from vmas_ros.bench.common import BENCHMARKS

__all__ = ["add_bench_arguments", "run_bench_command"]


# ---------------------------------------------------------------------- CLI
def add_bench_arguments(parser: argparse.ArgumentParser, with_benchmark_name: bool = True) -> argparse.ArgumentParser:
    """Add the ``bench`` options to ``parser``. With ``with_benchmark_name`` a positional
    benchmark name (only ``mpe`` today, default ``mpe``) is added first, for
    ``vmas-ros bench mpe ...``; pass False when ``mpe`` is already a subcommand."""
    if with_benchmark_name:
        parser.add_argument("benchmark", nargs="?", default="mpe", help="which benchmark: mpe (default)")
    # dest is not ``num_envs``: cli.main compares args.num_envs with an int
    parser.add_argument("--num-envs", dest="bench_num_envs", type=int, nargs="+", default=[1, 10, 100, 1000],
                        metavar="N", help="numbers of parallel envs (default: 1 10 100 1000)")
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
    return parser


def run_bench_command(args: argparse.Namespace) -> int:
    """Run the benchmark from parsed ``add_bench_arguments`` options: 0 on success, 2 on bad arguments."""
    # looked up on the module at call time (no import cycle; patches of vmas_ros.bench.mpe apply)
    from vmas_ros.bench import mpe

    benchmark = getattr(args, "benchmark", "mpe") or "mpe"
    if benchmark not in BENCHMARKS:
        print(f"vmas-ros bench: unknown benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}", file=sys.stderr)
        return 2
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
    plot = not getattr(args, "no_plot", False)
    if plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print("note: matplotlib is not installed (pip install 'vmas_ros[bench]'); no PNG will be written",
                  file=sys.stderr)
            plot = False
    rows = mpe.run_mpe_benchmark(progress=not getattr(args, "no_progress", False), **options)
    paths = mpe.write_results(rows, getattr(args, "out", "bench_results"), plot=plot)
    print(mpe.format_table(rows))
    print()
    for path in paths.values():
        print(f"wrote {path}")
    return 0
