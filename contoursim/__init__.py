"""contoursim: servo-loop contour error simulation for CNC machine tools."""

from .exceptions import ConfigError, PathError, TraceFormatError, UnstableLoopError
from .trajectory import Trajectory

__all__ = ["ConfigError", "PathError", "TraceFormatError", "UnstableLoopError", "Trajectory"]
