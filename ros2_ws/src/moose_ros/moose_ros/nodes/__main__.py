"""``python -m moose_ros.nodes NAME [--params FILE] [--param key=value ...]``: run one node."""
import sys

from . import NODES, main

if len(sys.argv) < 2:
    print(f"usage: python -m moose_ros.nodes NODE [--params FILE] [--param k=v]; nodes: {', '.join(NODES)}",
          file=sys.stderr)
    sys.exit(2)
main(sys.argv[1], sys.argv[2:])
