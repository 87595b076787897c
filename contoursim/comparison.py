"""Compensation strategies side by side on one machine and one reference: the figures of ``contoursim compare``.

Every strategy runs on the same machine and reference; the table gives, over
the test proper (:attr:`contoursim.trajectory.Trajectory.measuring`), the
max and RMS contour and tracking error, and over the whole run the peak
current command and whether the amplifier saturated, with the change of
the max contour error relative to ``none``. ``to_json`` gives the
comparison JSON of DESIGN.md (a contract: names and keys exact).
"""

import json
import warnings
from dataclasses import dataclass

import numpy as np

from .compensation import STRATEGY_NAMES, strategies_named
from .exceptions import ContoursimWarning, UnstableLoopError
from .model import as_model
from .simulation import simulate

__all__ = ["Comparison", "compare", "JSON_KEYS"]

#: Keys of each run in the comparison JSON (DESIGN.md contract).
JSON_KEYS = ("contour_max_um", "contour_rms_um", "tracking_max_um", "tracking_rms_um", "peak_current_A", "saturated")


def _figures(result):
    """One run's comparison figures (the JSON keys)."""
    summary = result.summary()
    response = result.servo_response
    figures = {key: summary[key] for key in JSON_KEYS[:4]}
    figures["peak_current_A"] = float(np.abs(response.current).max())
    figures["saturated"] = bool(response.saturated.any())
    return figures


@dataclass(frozen=True)
class Comparison:
    """The runs of a comparison, by strategy name (in the order run).

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
    """

    runs: dict

    @property
    def figures(self):
        """Strategy name -> the figures of :data:`JSON_KEYS` (errors [µm], current [A], saturated)."""
        return {name: _figures(result) for name, result in self.runs.items()}

    def to_json(self):
        """The comparison JSON (DESIGN.md contract), as text."""
        return json.dumps({"runs": self.figures}, indent=2)

    def table(self):
        """The comparison as a text table; the last column is the max contour error's change relative to ``none``.

        Where ``none`` has no contour error (a move along one axis), no change is relative to it: the column is empty.
        """
        figures = self.figures
        base = figures.get("none", {}).get("contour_max_um")
        head = (f"{'strategy':<24}{'contour max':>13}{'contour RMS':>13}{'tracking max':>14}{'tracking RMS':>14}"
                f"{'peak current':>14}{'saturated':>11}{'vs none':>11}")
        units = f"{'':<24}{'[µm]':>13}{'[µm]':>13}{'[µm]':>14}{'[µm]':>14}{'[A]':>14}{'':>11}{'[%]':>11}"
        lines = [head, units, "-" * len(head)]
        for name, f in figures.items():
            change = "" if not base or name == "none" else f"{100 * (f['contour_max_um'] / base - 1):+.4g}"
            lines.append(f"{name:<24}{f['contour_max_um']:>13.4g}{f['contour_rms_um']:>13.4g}{f['tracking_max_um']:>14.4g}"
                         f"{f['tracking_rms_um']:>14.4g}{f['peak_current_A']:>14.4g}{'yes' if f['saturated'] else 'no':>11}"
                         f"{change:>11}")
        return "\n".join(lines)


def compare(model, trajectory, names=STRATEGY_NAMES, design=None):
    """Run each named strategy on `model` following `trajectory`.

    Parameters
    ----------
    model : Model or Machine
        What is simulated (a machine with its effects).
    trajectory : Trajectory
        Sampled at the machine's servo period.
    names : sequence of str
        Strategy names (:func:`contoursim.compensation.strategies_named`),
        e.g. those of :data:`contoursim.compensation.STRATEGY_NAMES`.
    design : mapping str -> AxisServo, optional
        The servo model the strategies design from (default: the simulated
        servos themselves, a perfect model).

    Returns
    -------
    Comparison

    Raises
    ------
    ValueError
        An unknown name or combination, or the same name twice.
    UnstableLoopError
        A strategy destabilises the loop (the message names it).

    Warns
    -----
    ContoursimWarning
        A run's current command hit its limit (naming the strategy).
    """
    names = list(names)
    if not names:
        raise ValueError("compare needs at least one strategy name")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"strategy {twice[0]!r} is named twice")
    chain = as_model(model).machine.chain  # the geometric compensation's model: the machine file's errors
    strategies = {name: strategies_named(name, design, chain) for name in names}  # all checked first
    runs = {}
    for name, chosen in strategies.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ContoursimWarning)
            try:
                runs[name] = simulate(model, trajectory, chosen)
            except UnstableLoopError as exc:
                raise UnstableLoopError(f"strategy {name}: {exc}", margins=exc.margins) from None
        for warning in caught:
            warnings.warn(f"strategy {name}: {warning.message}", warning.category, stacklevel=2)
    return Comparison(runs)
