"""``moose can``: vehicle-bus tools with the DBC (``dump`` decodes live frames, ``replay`` sends a log)."""
from __future__ import annotations

import argparse
import sys
from typing import Any

from ..params import ParamError
from .common import positive_float


def add_subparser(subparsers: Any) -> None:
    can_parser = subparsers.add_parser("can", help="vehicle-bus tools (DBC config/kanon.dbc)")
    can_sub = can_parser.add_subparsers(dest="can_command", required=True)
    can_dump = can_sub.add_parser("dump", help="decode live frames with the DBC")
    can_dump.add_argument("--count", type=int, help="stop after this many frames")
    can_dump.add_argument("--duration", type=positive_float, help="stop after this many seconds")
    can_replay = can_sub.add_parser("replay", help="send a python-can log (.asc, .blf, .log, ...) onto the bus")
    can_replay.add_argument("file")
    can_replay.add_argument("--rate", type=positive_float, default=1.0)
    for parser_ in (can_dump, can_replay):
        parser_.add_argument("--interface", default="udp_multicast", help="socketcan, udp_multicast or virtual")
        parser_.add_argument("--channel", help="multicast group or socketcan device (default: the "
                                               "udp_multicast bus's group, moose.canbus.bus.DEFAULT_GROUP)")
        parser_.add_argument("--port", type=int,
                             help="UDP port of udp_multicast (default: moose.canbus.bus.DEFAULT_PORT)")
        parser_.set_defaults(func=cmd_can)


def cmd_can(args: argparse.Namespace) -> int:
    import can

    from ..canbus.bus import DEFAULT_GROUP, open_bus
    from ..canbus.tools import dump, replay

    channel = args.channel or DEFAULT_GROUP
    try:
        bus = open_bus(args.interface, channel, port=args.port)
    except ValueError as exc:
        raise ParamError(str(exc)) from None
    except (can.CanError, OSError) as exc:  # no such device, no SocketCAN in this kernel, the port taken
        raise ParamError(f"--interface {args.interface} --channel {channel!r}: the bus cannot be opened: "
                         f"{exc}") from None
    try:
        if args.can_command == "dump":
            dump(bus, sys.stdout, count=args.count, duration=args.duration)
        else:
            try:
                print(f"sent {replay(args.file, bus, rate=args.rate)} frames")
            except FileNotFoundError as exc:
                raise ParamError(str(exc)) from None
    except KeyboardInterrupt:
        pass
    finally:
        bus.shutdown()
    return 0
