"""contoursim: servo-loop contour error simulation for CNC machine tools.

The main objects, by the data flow of a simulation:

- paths and feed: :mod:`contoursim.paths` (geometry), :mod:`contoursim.feed`
  (:func:`~contoursim.feed.plan`, :func:`~contoursim.feed.sample` -> :class:`Trajectory`),
  :func:`~contoursim.pathfile.load_path_file`, :func:`~contoursim.gcode.read_gcode`;
- servo: :class:`AxisServo` (python-control models), :func:`contoursim.kernel.run`;
- machine: :class:`Machine`, :func:`load_machine` (servo axes + multibody geometry);
- effects: :class:`Effect` (the catalogue, :mod:`contoursim.effects`), :class:`Model`
  (a machine plus effects), :func:`load_model` (a machine file with its ``[[effect]]`` tables);
- compensation strategies (:mod:`contoursim.compensation`): :class:`Feedforward`,
  :class:`ZPETC`, :class:`CrossCoupled` (in the loop), composable with each other and with
  :class:`~contoursim.geocomp.GeometricCompensation`; :func:`~contoursim.comparison.compare`
  runs them side by side;
- :func:`simulate` -> :class:`SimResult` (tracking and exact contour error), on a path or a
  measured trace; :func:`simulate_batch` (variants of one model in one compiled call);
- traces: :func:`read_trace`, :func:`write_trace` (the measured-trace CSV format);
- diagnosis: :func:`diagnose` -> :class:`Diagnosis` (which catalogue effects a nominal model
  lacks to explain a measured trace; :mod:`contoursim.diagnosis`).
"""

import importlib

from ._version import __version__
from .exceptions import ConfigError, PathError, TraceFormatError, UnstableLoopError

# name -> submodule: imported on first use, so that ``import contoursim`` and
# ``contoursim --help`` do not load python-control, scipy and numba
_LAZY = {
    "AxisServo": "servo",
    "CrossCoupled": "compensation",
    "Diagnosis": "diagnosis",
    "Feedforward": "compensation",
    "ZPETC": "compensation",
    "Effect": "effects",
    "Machine": "machine",
    "Model": "model",
    "SimResult": "simulation",
    "Trace": "traces",
    "Trajectory": "trajectory",
    "diagnose": "diagnosis",
    "load_machine": "machine",
    "load_model": "model",
    "read_trace": "traces",
    "simulate": "simulation",
    "simulate_batch": "simulation",
    "write_trace": "traces",
}

__all__ = [
    "AxisServo",
    "ConfigError",
    "CrossCoupled",
    "Diagnosis",
    "Effect",
    "Feedforward",
    "Machine",
    "Model",
    "PathError",
    "SimResult",
    "Trace",
    "TraceFormatError",
    "Trajectory",
    "UnstableLoopError",
    "ZPETC",
    "diagnose",
    "load_machine",
    "load_model",
    "read_trace",
    "simulate",
    "simulate_batch",
    "write_trace",
]


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module 'contoursim' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))

