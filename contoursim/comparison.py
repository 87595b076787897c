"""Compensation strategies side by side on one machine and one reference: the figures of ``contoursim compare``.

Every strategy runs on the same machine and reference; the table gives, over
the test proper (:attr:`contoursim.trajectory.Trajectory.measuring`), the
max and RMS contour and tracking error, and over the whole run the peak
current command, on how many samples the amplifier's current limit bound,
the coupled loop's margins (a cross-coupled strategy) and the change of the
max contour error relative to ``none``. Its header gives the axes' loop
margins, every strategy's settings and how its gains were chosen: designed
(:func:`contoursim.coupled_loop.designed_gains`, common to the strategies),
set (a job file's ``[[strategy]]`` tables, ``--set``) or tuned on the path
(:func:`tune`). ``to_json`` gives the comparison JSON of DESIGN.md (a
contract: names and keys exact; the settings, margins and clamped share are
added fields).
"""

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .compensation import STRATEGY_NAMES, Composition, strategies_named
from .exceptions import ContoursimWarning, UnstableLoopError
from .model import as_model
from .output import json_text
from .simulation import simulate

__all__ = ["Comparison", "compare", "tune", "JSON_KEYS", "JSON_FORM", "TUNE_KP_START", "TUNE_KP_STEP", "TUNE_KP_END",
           "TUNE_KI_FACTORS"]

#: Keys of each run in the comparison JSON (DESIGN.md contract).
JSON_KEYS = ("contour_max_um", "contour_rms_um", "tracking_max_um", "tracking_rms_um", "peak_current_A", "saturated")
#: The form of the comparison JSON (:func:`contoursim.output.has_form`): ``compare --json`` replaces only a file of it.
JSON_FORM = {"runs": JSON_KEYS, "axes": ("phase_margin_deg", "damping_ratio")}

#: A strategy whose max contour error exceeds this many times that of ``none`` is warned of (:func:`compare`):
#: compensation that doubles the worst error is not compensating.
WORSE = 2.0
#: :func:`tune`'s coupling gains: ``kp`` from this many times the smallest position gain ``Kp`` of the coupled axes [-] ...
TUNE_KP_START = 0.25
#: ... in steps of this factor [-] ...
TUNE_KP_STEP = 2.0**0.5
#: ... up to the first refused by the check or this many times ``Kp`` [-];
TUNE_KP_END = 64.0
#: then ``ki`` = these times ``K^2`` at the best ``kp`` (``K = Kp + kp``; the design's is 1/4) [-].
TUNE_KI_FACTORS = (0.0, 1.0 / 16.0, 1.0)


_RESOLUTION = 0.0005  # half the nm the trace CSV holds [µm]: an error below it is shown as <0.001


def _nm(error):
    """An error [µm] to the nm the trace CSV holds; ``<0.001`` below it."""
    return "<0.001" if error < _RESOLUTION else f"{error:.3f}"


def _figures(result):
    """One run's comparison figures (the JSON keys, then the share of samples whose current command was clamped)."""
    summary = result.summary()
    response = result.servo_response
    figures = {key: summary[key] for key in JSON_KEYS[:4]}
    figures["peak_current_A"] = float(np.abs(response.current).max())
    figures["saturated"] = bool(response.saturated.any())
    figures["clamped_pct"] = 100.0 * float(response.saturated.any(axis=1).mean())
    return figures


def _coupled_margins(result):
    """The coupled loop's margins along the run's path (:meth:`CrossCoupled.margins`), ``None`` without a coupling."""
    coupling = [s for s in result.strategies if s.kind == "coupling"]
    if not coupling:
        return None
    model = result.model
    servos = Composition(result.strategies).drive(model.servos())
    coupled = dict(list(servos.items())[:3])
    columns = model.machine.servo_columns[: len(coupled)]
    return coupling[0].margins(result.axis_command[:, columns], coupled, model.machine.servo_period)


def _settings(result):
    """Each strategy's settings in the run, by strategy name (file keys, :data:`contoursim.compensation.STRATEGY_KEYS`)."""
    model = result.model
    servos = Composition(result.strategies).drive(model.servos())
    settings = {s.name: s.settings(servos, model.machine.servo_period) for s in result.strategies}
    return {name: values for name, values in settings.items() if values}


@dataclass(frozen=True)
class Comparison:
    """The runs of a comparison, by strategy name (in the order run).

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
    gains : dict of str -> str, optional
        How each run's coupling gains were chosen (``"designed"``,
        ``"set"``, ``"tuned"``), for the runs with a coupling.
    """

    runs: dict
    gains: dict = field(default_factory=dict)

    @cached_property
    def figures(self):
        """Strategy name -> the figures of :data:`JSON_KEYS` (errors [µm], current [A], saturated), ``clamped_pct`` [%]."""
        return {name: _figures(result) for name, result in self.runs.items()}

    @cached_property
    def coupled_loops(self):
        """Strategy name -> its coupled loop's margins along the path (see :meth:`CrossCoupled.margins`), or ``None``."""
        return {name: _coupled_margins(result) for name, result in self.runs.items()}

    @cached_property
    def settings(self):
        """Strategy name -> each of its parts' settings (part -> file key -> value, see :meth:`Strategy.settings`)."""
        return {name: _settings(result) for name, result in self.runs.items()}

    @cached_property
    def axis_loops(self):
        """Axis name -> its sampled position loop's ``phase_margin_deg`` and ``damping_ratio`` [-] (as simulated)."""
        result = next(iter(self.runs.values()))
        dt = result.machine.servo_period
        loops = {axis: servo.margins(dt)["position"] for axis, servo in result.model.servos().items()}
        return {axis: {"phase_margin_deg": m["phase_margin"], "damping_ratio": m["damping_ratio"]}
                for axis, m in loops.items()}

    def to_json(self):
        """The comparison JSON (DESIGN.md contract, with added fields), as text.

        Each run has the contract's keys, then ``clamped_pct``, ``settings``
        (strategy -> file key -> value), and with a coupling ``gains``
        (how they were chosen) and ``coupled_loop`` (``phase_margin_deg``,
        ``gain_margin``, ``damping_ratio``, ``spectral_radius``, ``frames``);
        ``axes`` gives each axis's position-loop margins. Strict JSON: a margin
        that does not exist (a loop gain that never crosses 1: infinite) is ``null``.
        """
        runs = {}
        loops = self.coupled_loops
        for name, figures in self.figures.items():
            run = dict(figures, settings=self.settings[name])
            if loops[name] is not None:
                m = loops[name]
                run["gains"] = self.gains.get(name, "designed")
                run["coupled_loop"] = {"phase_margin_deg": m["phase_margin"], "gain_margin": m["gain_margin"],
                                       "damping_ratio": m["damping_ratio"],
                                       "spectral_radius": m["spectral_radius"], "frames": m["frames"]}
            runs[name] = run
        return json_text({"runs": runs, "axes": self.axis_loops})

    def header(self):
        """The lines above the table: the axes' loop margins, how the gains were chosen, every strategy's settings."""
        axes = "; ".join(f"{axis}: phase margin {m['phase_margin_deg']:.1f}°, ζ {m['damping_ratio']:.2f}"
                         for axis, m in self.axis_loops.items())
        lines = [f"axis position loops (sampled): {axes}"]
        coupled = [name for name, loop in self.coupled_loops.items() if loop is not None]
        if coupled:
            how = {}
            for name in coupled:
                how.setdefault(self.gains.get(name, "designed"), []).append(name)
            text = {"designed": "designed for ζ = 0.7 on the sampled coupled loop (common to the strategies)",
                    "set": "set by the job file or --set", "tuned": "tuned on this path, each strategy its own (tune)"}
            lines.append("coupling gains: " + "; ".join(f"{', '.join(names)} {text.get(origin, origin)}"
                                                        for origin, names in how.items()))
            lines.append("coupled loop: phase margin and ζ the worst over the directions the path's normal takes "
                         "(checked like an axis loop: >= 30°, >= 0.2)")
        for name, parts in self.settings.items():
            values = []
            for part, settings in parts.items():
                text = ", ".join(f"{key} = {value:.4g}" for key, value in settings.items())
                values.append(text if part == name else f"{part} {text}")
            if values:
                lines.append(f"  {name}: " + "; ".join(values))
        return "\n".join(lines)

    def table(self):
        """The comparison as a text table; the last column is the max contour error's change relative to ``none``.

        Errors to the nm (0.001 µm, the trace CSV's resolution); ``clamped``
        is the share of the run's samples on which an axis's current
        command was clamped at its limit; ``PM`` and ``ζ`` those of the
        coupled loop along the path. Where ``none`` has no contour error to the
        nm (a move along one axis), no change is relative to it: the column is empty.
        """
        figures, loops = self.figures, self.coupled_loops
        base = figures.get("none", {}).get("contour_max_um")
        first = max([22] + [len(name) + 2 for name in figures])  # a long composition's name keeps the columns in line
        head = (f"{'strategy':<{first}}{'contour max':>12}{'contour RMS':>12}{'tracking max':>13}{'tracking RMS':>13}"
                f"{'peak current':>13}{'clamped':>9}{'PM':>7}{'ζ':>6}{'vs none':>9}")
        units = f"{'':<{first}}{'[µm]':>12}{'[µm]':>12}{'[µm]':>13}{'[µm]':>13}{'[A]':>13}{'[%]':>9}{'[°]':>7}{'':>6}{'[%]':>9}"
        lines = [self.header(), "", head, units, "-" * len(head)]
        for name, f in figures.items():
            change = "" if not base or base < 5e-4 or name == "none" else f"{100 * (f['contour_max_um'] / base - 1):+.1f}"
            loop = loops[name]
            margins = f"{'':>7}{'':>6}" if loop is None else f"{loop['phase_margin']:>7.1f}{loop['damping_ratio']:>6.2f}"
            errors = "".join(f"{_nm(f[key]):>{width}}" for key, width in
                             (("contour_max_um", 12), ("contour_rms_um", 12), ("tracking_max_um", 13), ("tracking_rms_um", 13)))
            lines.append(f"{name:<{first}}{errors}{f['peak_current_A']:>13.3g}{f['clamped_pct']:>9.2f}{margins}{change:>9}")
        return "\n".join(lines)


def _run(model, trajectory, name, strategies):
    """``simulate`` with the strategy's name on its warnings and errors."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContoursimWarning)
        try:
            result = simulate(model, trajectory, strategies)
        except UnstableLoopError as exc:
            raise UnstableLoopError(f"strategy {name}: {exc}", margins=exc.margins) from None
    return result, caught


def tune(model, trajectory, name, design=None, settings=None):
    """Coupling gains of strategy `name` with the least max contour error on `trajectory` that the coupled-loop check passes.

    A search on the path itself, each candidate simulated: ``kp`` from
    :data:`TUNE_KP_START` times the smallest position gain ``Kp`` of the
    coupled axes in steps of :data:`TUNE_KP_STEP` with the design's
    ``ki = K^2/4`` (``K = Kp + kp``), up to the first gain the coupled-loop
    check refuses (:meth:`CrossCoupled.coupling`: unstable, phase margin
    < 30° or ζ < 0.2 along the path); at the best ``kp``, ``ki`` =
    :data:`TUNE_KI_FACTORS` times ``K^2``; then ``kp`` half a step either
    side of the best. The lowest max contour error wins; a refused
    candidate is skipped.

    Parameters
    ----------
    model : Model or Machine
    trajectory : Trajectory
    name : str
        A strategy name with a cross-coupled part, e.g. ``"ccc_arc"`` or ``"feedforward+ccc_arc"``.
    design : mapping str -> AxisServo, optional
        The servo model the strategies design from.
    settings : mapping, optional
        The other settings (as for :func:`contoursim.compensation.strategies_named`).

    Returns
    -------
    dict
        ``settings`` (`settings` with the tuned ``kp_per_s``, ``ki_per_s2``
        of the coupled part, by the keys of
        :data:`contoursim.compensation.STRATEGY_KEYS`), ``max_contour_um`` at
        them, and ``tried``: a list of ``(kp [1/s], ki [1/s^2], contour max
        [µm] or None where refused)``.

    Raises
    ------
    ValueError
        `name` has no cross-coupled part, or every candidate was refused.
    """
    chain = as_model(model).machine.chain
    settings = {part: dict(values) for part, values in (settings or {}).items()}
    parts = [part for part in name.split("+") if part.startswith("ccc_")]
    if not parts:
        raise ValueError(f"strategy {name!r} has no cross-coupled part to tune")
    part = parts[0]
    coupled = list(as_model(model).servos().values())[:3] if design is None else list(design.values())[:3]
    position_gain = min(servo.kp for servo in coupled)
    tried, best = [], None

    def attempt(kp, ki_factor):
        """Simulate with kp, ki = ki_factor·K^2; whether the check let it run."""
        nonlocal best
        ki = ki_factor * (position_gain + kp) ** 2
        if any(kp == k and ki == i for k, i, _ in tried):
            return True
        chosen = {**settings, part: {**settings.get(part, {}), "kp_per_s": kp, "ki_per_s2": ki}}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ContoursimWarning)
            try:
                result = simulate(model, trajectory, strategies_named(name, design, chain, chosen))
            except UnstableLoopError:
                tried.append((kp, ki, None))
                return False
        error = result.summary()["contour_max_um"]
        tried.append((kp, ki, error))
        if best is None or error < best[0]:
            best = (error, kp, ki, ki_factor)
        return True

    factor = TUNE_KP_START
    while factor <= TUNE_KP_END and attempt(factor * position_gain, 0.25):  # up to the first gain refused
        factor *= TUNE_KP_STEP
    if best is None:
        raise ValueError(f"no coupling gain of {name} passes the coupled-loop check on this path: set them")
    for ki_factor in TUNE_KI_FACTORS:
        attempt(best[1], ki_factor)
    kp, ki_factor = best[1], best[3]
    for step in (TUNE_KP_STEP**-0.5, TUNE_KP_STEP**0.5):
        attempt(kp * step, ki_factor)
    error, kp, ki = best[:3]
    settings[part] = {**settings.get(part, {}), "kp_per_s": kp, "ki_per_s2": ki}
    return {"settings": settings, "max_contour_um": error, "tried": tried}


def compare(model, trajectory, names=STRATEGY_NAMES, design=None, settings=None, tuned=False):
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
    settings : mapping str -> mapping, optional
        Each strategy part's settings by the keys of a job file's
        ``[[strategy]]`` table (as for
        :func:`~contoursim.compensation.strategies_named`, e.g.
        ``{"ccc_arc": {"kp_per_s": 120.0}}``), common to every run it is part of.
    tuned : bool or mapping str -> mapping
        ``True``: each strategy with a coupling gets its own gains tuned on
        `trajectory` first (:func:`tune`); a mapping: strategy name ->
        its settings from an earlier :func:`tune` (e.g. on the nominal
        machine), used as they are.

    Returns
    -------
    Comparison

    Raises
    ------
    ValueError
        An unknown name or combination, the same name twice, or settings of a strategy none of `names` has.
    UnstableLoopError
        A strategy destabilises the loop (the message names it).

    Warns
    -----
    ContoursimWarning
        A run's current command hit its limit (naming the strategy); a
        strategy's max contour error is more than :data:`WORSE` times that of
        ``none`` (run beside it): no check before the run sees a cross-coupled
        controller hold the tool on a line the path has left (a corner that
        turns back) while the position loops pull it back along the path.
    """
    if isinstance(names, str):  # its letters would be the names
        raise TypeError(f"names must be a sequence of strategy names, e.g. ('none', 'ccc_arc'), got the string {names!r}")
    if settings is not None and not isinstance(settings, Mapping):
        raise TypeError(f"settings must map strategy names to their settings, got {type(settings).__name__}")
    if not isinstance(tuned, (bool, np.bool_, Mapping)):
        raise TypeError(f"tuned must be True, False or a mapping of strategy names to tuned settings, got {tuned!r}")
    names = list(names)
    if not names:
        raise ValueError("compare needs at least one strategy name")
    seen = {}
    for name in filter(lambda n: isinstance(n, str), names):  # its parts in another order too: the same run
        parts = frozenset(name.split("+"))
        if parts in seen:
            raise ValueError(f"strategy {name!r} is named twice" if seen[parts] == name else
                             f"strategy {name!r} is {seen[parts]!r}, named twice (a composition's parts act in their "
                             "stages whatever their order)")
        seen[parts] = name
    chain = as_model(model).machine.chain  # the geometric compensation's model: the machine file's errors
    settings = dict(settings or {})
    if tuned is True:
        fixed = [f"{part}.{key}" for part, values in settings.items() if part.startswith("ccc_")
                 for key in ("kp_per_s", "ki_per_s2") if key in values]
        if fixed:
            raise ValueError(f"tuning sets the coupling's kp_per_s and ki_per_s2: {fixed[0]} is set as well; drop one "
                             "of them")
    chosen = {name: settings for name in names}
    strategies = {name: strategies_named(name, design, chain, settings) for name in names}  # all checked first
    unused = [part for part in settings if part not in {p for name in names for p in name.split("+")}]
    if unused:  # its settings would be dropped without a word
        raise ValueError(f"settings of {unused[0]!r}, which none of the strategies {', '.join(names)} has: run it, or "
                         "drop its settings")
    gains = {}
    for name, made in strategies.items():
        coupling = [s for s in made if s.kind == "coupling"]
        if not coupling:
            continue
        if tuned is True:
            chosen[name] = tune(model, trajectory, name, design, settings)["settings"]
        elif tuned and name in tuned:
            chosen[name] = tuned[name]
        gains[name] = "tuned" if chosen[name] is not settings else coupling[0].gains_origin
        strategies[name] = strategies_named(name, design, chain, chosen[name])
    runs = {}
    for name, made in strategies.items():
        runs[name], caught = _run(model, trajectory, name, made)
        for warning in caught:
            warnings.warn(f"strategy {name}: {warning.message}", warning.category, stacklevel=2)
    if "none" in runs:
        worst = {name: run.summary()["contour_max_um"] for name, run in runs.items()}
        for name, value in worst.items():
            # below the table's resolution (a path along one axis: none's error is exactly 0) nothing is worse
            if value > WORSE * max(worst["none"], _RESOLUTION):
                why = ("; where the path turns back at a corner, a coupling's correction can hold the tool on the "
                       "line the path left while the position loops pull it back along the path and the tracking "
                       "error grows, until its estimate's search (twice the tracking error about the commanded point) "
                       "reaches the commanded part of the path and the tool crosses to it" if "ccc" in name else "")
                times = f"is {value / worst['none']:.3g} times" if worst["none"] >= _RESOLUTION else "exceeds"
                warnings.warn(f"strategy {name}: its max contour error, {value:.4g} µm, {times} that without compensation "
                              f"({_nm(worst['none'])} µm){why}", ContoursimWarning, stacklevel=2)
    return Comparison(runs, gains)
