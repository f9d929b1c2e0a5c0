"""ROS 2 bags (MCAP storage) of the graph: write, read (also after a crash), record, play, export, re-plan.

Bags are ROS 2 bag directories (``metadata.yaml`` + ``.mcap``), CDR messages with their definitions
embedded, so ``ros2 bag info/play``, rosbags and Foxglove open them.  Only public APIs of ``mcap`` and
``rosbags`` are used.

Modules: :mod:`.writer` (:class:`BagWriter`: chunks with checksums, a valid bag at every checkpoint),
:mod:`.reader` (:class:`BagReader`, :func:`read_bag`: damaged chunks skipped, unfinished and cut files read to
their end, types from the bag's own definitions, a :class:`ReadReport` of everything that could not be read;
:func:`bag_info`), :mod:`.record` (:class:`Recorder` of a running graph,
:func:`record_result` of a lockstep run, :func:`record_simulation`: the recorder plugin of ``moose
simulate``), :mod:`.params` (the run's parameters kept in the bag), :mod:`.play`, :mod:`.export` (CSV,
Parquet), :mod:`.replan` (open-loop re-planning and its figure), :mod:`.view` (bird's-eye view).
"""
from .errors import BagError
from .export import export, flatten
from .params import RunParameters, read_run_parameters
from .play import LockstepStuck, play
from .reader import BagMessage, BagReader, ReadReport, bag_info, read_bag
from .record import Recorder, record_result, record_simulation
from .replan import plot_replan, replan
from .view import plot_birdseye
from .writer import BagWriter

__all__ = [
    "BagError", "BagMessage", "BagReader", "BagWriter", "LockstepStuck", "ReadReport", "Recorder", "RunParameters",
    "bag_info", "export", "flatten", "play", "plot_birdseye", "plot_replan", "read_bag", "read_run_parameters",
    "record_result", "record_simulation", "replan",
]
