"""The ``vmas-ros`` subcommands of the ROS tools: their options and how they report failure.

Every tool prints what it did on stdout; a refusal is one line on stderr,
prefixed with the command, and a non-zero exit code (2 for bad arguments, 1
for a graph that does not have what was asked for).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable

from vmas_ros.rostools.graph import ToolError

__all__ = ["add_rostool_parsers"]

NAMESPACE_HELP = "namespace that relative names resolve against, as in ros2 (default /)"


def _graph_options(parser: argparse.ArgumentParser, waits_for: str, timeout: float = 10.0) -> None:
    """``--timeout`` (how long to wait for ``waits_for``) and ``--namespace``, as every graph tool takes."""
    parser.add_argument("--timeout", type=float, default=timeout,
                        help=f"seconds to wait for {waits_for} (default {timeout:g})")
    parser.add_argument("--namespace", default="/", help=NAMESPACE_HELP)


def _run(name: str, body: Callable[[argparse.Namespace], object]) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        try:
            body(args)
        except ToolError as error:
            print(f"vmas-ros {name}: {error}", file=sys.stderr)
            return error.exit_code
        except KeyboardInterrupt:
            return 130
        return 0
    return run


def _echo(args: argparse.Namespace) -> None:
    from vmas_ros.rostools.echo import echo

    echo(args.topic, count=args.count, timeout=args.timeout, namespace=args.namespace)


def _drive(args: argparse.Namespace) -> None:
    from vmas_ros.rostools.drive import drive

    drive(args.agent, args.vx, args.vy, args.wz, args.seconds, rate_hz=args.rate, wait=args.wait,
          namespace=args.namespace)


def _topics(args: argparse.Namespace) -> None:
    from vmas_ros.rostools.topics import list_topics

    list_topics(wait=args.wait, services=args.services, show_types=not args.no_types)


def _call(args: argparse.Namespace) -> None:
    from vmas_ros.rostools.call import call

    if not call(args.service, args.value, timeout=args.timeout, namespace=args.namespace):
        raise ToolError(f"{args.service} answered success=False")


def _param(args: argparse.Namespace) -> None:
    from vmas_ros.rostools import param

    common = dict(timeout=args.timeout, namespace=args.namespace)
    needs = {"list": 0, "get": 1, "describe": 1, "set": 2}[args.action]
    given = [v for v in (args.name, args.value) if v is not None]
    if len(given) != needs:
        usage = {"list": "NODE", "get": "NODE NAME", "describe": "NODE NAME", "set": "NODE NAME VALUE"}[args.action]
        raise ToolError(f"param {args.action} takes {usage}", 2)
    if args.action == "list":
        param.list_parameters(args.node, **common)
    elif args.action == "get":
        param.get_parameter(args.node, args.name, **common)
    elif args.action == "describe":
        param.describe_parameter(args.node, args.name, **common)
    else:
        param.set_parameter(args.node, args.name, args.value, **common)


def _bag(args: argparse.Namespace) -> None:
    if args.action == "info":
        from vmas_ros.rostools.bag import bag_info

        bag_info(args.path, as_json=args.json)
    else:
        from vmas_ros.rostools.bag_play import play

        play(args.path, rate=args.rate, topics=args.topics, delay=args.delay, progress=not args.quiet)


def _dds_clean(args: argparse.Namespace) -> None:
    from vmas_ros.rostools.dds_clean import clean

    if args.min_age < 0:
        raise ToolError(f"--min-age must be >= 0 seconds, got {args.min_age}", 2)
    clean(args.dir, min_age_s=args.min_age, dry_run=args.dry_run)


def add_rostool_parsers(sub) -> None:
    """Add ``echo``, ``drive``, ``topics``, ``call``, ``param``, ``bag`` and ``dds-clean`` to the
    ``vmas-ros`` subparsers ``sub``."""
    echo = sub.add_parser("echo", help="print messages of a topic (ros2 topic echo)",
                          description="Print messages of a topic, each followed by ---. With a full ROS install: "
                                      "ros2 topic echo TOPIC.")
    echo.add_argument("topic", help="topic name, absolute (/agent_0/scan) or relative (agent_0/scan)")
    echo.add_argument("--count", type=int, default=1, help="messages to print (default 1)")
    _graph_options(echo, "them")
    echo.set_defaults(func=_run("echo", _echo))
    drive = sub.add_parser(
        "drive", help="drive an agent: a Twist on <agent>/cmd_vel for a while",
        description="Wait until <agent>/cmd_vel has a subscriber, publish the velocity for --seconds of wall time "
                    "(--rate commands per second), then a zero command, and report what was sent. Publishes "
                    "TwistStamped where the node asks for it (use_stamped_cmd_vel). With a full ROS install: "
                    "ros2 topic pub, or teleop_twist_keyboard.")
    drive.add_argument("agent", nargs="?", default="agent_0",
                       help="agent name, relative (agent_0) or absolute (/swarm1/agent_0) (default agent_0)")
    drive.add_argument("--vx", type=float, default=0.0, help="forward speed, m/s (body frame)")
    drive.add_argument("--vy", type=float, default=0.0, help="leftward speed, m/s (body frame)")
    drive.add_argument("--wz", type=float, default=0.0, help="yaw rate, rad/s (counter-clockwise)")
    drive.add_argument("--seconds", type=float, default=2.0, help="how long to drive, wall time (default 2)")
    drive.add_argument("--rate", type=float, default=20.0, help="commands per second (default 20)")
    drive.add_argument("--wait", type=float, default=10.0, help="seconds to wait for a subscriber (default 10)")
    drive.add_argument("--namespace", default="/", help=NAMESPACE_HELP)
    drive.set_defaults(func=_run("drive", _drive))
    topics = sub.add_parser("topics", help="list the topics of the ROS graph with their types (ros2 topic list -t)",
                            description="List every topic (or, with --services, service) of the ROS graph with "
                                        "its types, after --wait seconds of discovery. With a full ROS install: "
                                        "ros2 topic list -t, ros2 service list -t.")
    topics.add_argument("--services", action="store_true", help="list services instead of topics")
    topics.add_argument("--no-types", action="store_true", help="names only")
    topics.add_argument("--wait", type=float, default=3.0,
                        help="seconds of discovery before listing (default 3: a node can take 2 s to be seen)")
    topics.set_defaults(func=_run("topics", _topics))
    call = sub.add_parser("call", help="call a std_srvs Trigger, SetBool or Empty service (ros2 service call)",
                          description="Call a std_srvs Trigger, SetBool (VALUE true or false) or Empty service and "
                                      "print the reply; exit code 1 when it answers success=False. sim_node's: "
                                      "/sim_node/reset, /sim_node/pause true|false, /sim_node/step. With a full "
                                      "ROS install: ros2 service call.")
    call.add_argument("service", help="service name, e.g. /sim_node/reset or sim_node/pause")
    call.add_argument("value", nargs="?", default=None, help="true or false, for a SetBool service")
    _graph_options(call, "the service")
    call.set_defaults(func=_run("call", _call))
    param = sub.add_parser("param", help="list, get, describe or set a node's parameters (ros2 param)",
                           description="A node's parameters through its parameter services. set reads VALUE as "
                                       "YAML (1, 1.5, true, [1, 2], text). With a full ROS install: ros2 param.")
    param.add_argument("action", choices=("list", "get", "describe", "set"))
    param.add_argument("node", help="node name, e.g. /sim_node")
    param.add_argument("name", nargs="?", default=None, help="parameter name (get, describe, set)")
    param.add_argument("value", nargs="?", default=None, help="new value (set)")
    _graph_options(param, "the node")
    param.set_defaults(func=_run("param", _param))
    bag = sub.add_parser("bag", help="what a bag holds, or play it back (ros2 bag info|play)",
                         description="info: files, size, duration, start, end and per-topic types and counts of an "
                                     ".mcap file or bag folder. play: publish its messages again with their "
                                     "recorded timing. With a full ROS install: ros2 bag info|play.")
    bag.add_argument("action", choices=("info", "play"))
    bag.add_argument("path", help="an .mcap file or a rosbag2 bag folder")
    bag.add_argument("--json", action="store_true", help="info: print JSON")
    bag.add_argument("--rate", type=float, default=1.0, help="play: speed factor (default 1)")
    bag.add_argument("--topics", nargs="+", default=None, help="play: only these topics")
    bag.add_argument("--delay", type=float, default=0.5,
                     help="play: seconds between creating the publishers and the first message, for running "
                          "subscribers to discover them (default 0.5)")
    bag.add_argument("--quiet", action="store_true", help="play: no progress bar")
    bag.set_defaults(func=_run("bag", _bag))
    dds = sub.add_parser("dds-clean", help="remove Fast DDS shared memory that a killed process left half made",
                         description="A ROS process killed while it set up Fast DDS's shared memory leaves a "
                                     "segment under /dev/shm that makes every later node hang at start-up, with "
                                     "no output. This removes such segments (ones still not ready after "
                                     "--min-age seconds) and nothing else. With a full ROS install: "
                                     "fastdds shm clean.")
    dds.add_argument("--dry-run", action="store_true", help="list the stuck segments, remove nothing")
    dds.add_argument("--min-age", type=float, default=2.0,
                     help="seconds a segment must have stayed unready (default 2; setting one up takes "
                          "microseconds)")
    dds.add_argument("--dir", type=Path, default=Path("/dev/shm"), help="where Fast DDS keeps them (default /dev/shm)")
    dds.set_defaults(func=_run("dds-clean", _dds_clean))
