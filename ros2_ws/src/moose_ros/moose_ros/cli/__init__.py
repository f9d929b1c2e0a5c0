"""The node graph's commands of ``moose``, registered as plugins (entry point group ``moose.commands``):
``moose node`` (:mod:`.node`), ``moose launch`` (:mod:`.launch`) and ``moose bag`` (:mod:`.bag`).

Each module defines ``add_subparser(subparsers)``; the middleware, the planners and the bag
libraries are imported by the handlers only, so ``moose --help`` stays quick and a node started
with ``moose node`` loads only what its job needs.
"""
