"""contoursim: servo-loop contour error simulation for CNC machine tools.

The main objects, by the data flow of a simulation:

- paths and feed: :mod:`contoursim.paths` (geometry), :mod:`contoursim.feed`
  (:func:`~contoursim.feed.plan`, :func:`~contoursim.feed.sample` -> :class:`Trajectory`),
  :func:`~contoursim.pathfile.load_path_file`, :func:`~contoursim.gcode.read_gcode`;
- servo: :class:`AxisServo` (python-control models), :func:`contoursim.kernel.run`;
- machine: :class:`Machine`, :func:`load_machine` (servo axes + multibody geometry);
- :func:`simulate` -> :class:`SimResult` (tracking and exact contour error);
- traces: :func:`read_trace`, :func:`write_trace` (the measured-trace CSV format).
"""

from ._version import __version__
from .exceptions import ConfigError, PathError, TraceFormatError, UnstableLoopError
from .traces import Trace, read_trace, write_trace
from .machine import Machine, load_machine
from .servo import AxisServo
from .simulate import SimResult, simulate
from .trajectory import Trajectory

__all__ = [
    "AxisServo",
    "ConfigError",
    "Machine",
    "PathError",
    "SimResult",
    "Trace",
    "TraceFormatError",
    "Trajectory",
    "UnstableLoopError",
    "load_machine",
    "read_trace",
    "simulate",
    "write_trace",
]
