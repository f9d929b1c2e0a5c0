"""``moose node NAME``: run one node of the graph (Cyclone DDS, or rclpy when installed)."""
from __future__ import annotations

import argparse
from typing import Any

from ..graph import NODES


def add_subparser(subparsers: Any) -> None:
    node = subparsers.add_parser("node", help="run one node of the graph (Cyclone DDS, or rclpy when installed)")
    node.add_argument("name", help=", ".join(NODES))
    node.add_argument("--params", help="ROS 2 parameter file")
    node.add_argument("--param", action="append", default=[], help="parameter override key=value")
    node.set_defaults(func=cmd_node)


def cmd_node(args: argparse.Namespace) -> int:
    from ..nodes import run

    argv = (["--params", args.params] if args.params else []) + [a for p in args.param for a in ("--param", p)]
    return int(run(args.name, argv))
