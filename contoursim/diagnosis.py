"""Diagnosis: where a measured trace and the nominal model disagree, which catalogue effect closes the gap.

The workflow (:func:`diagnose`):

1. **Load** a measured trace and a nominal :class:`~contoursim.model.Model`;
   without one, identify the nominal loops from the trace
   (:func:`contoursim.identify.identify_machine`: one position gain shared
   by all axes, so that a ``gain_mismatch`` stays visible).
2. **Compare**: simulate the nominal model on the measured reference
   (:func:`~contoursim.simulation.measured_reference`); residual = measured −
   simulated, per axis and along the path normal; :func:`locate` says where
   it concentrates and what it correlates with.
3. **Refit the nominal model**: real machines differ from their nominal
   model by a few % in masses and damping, and a measuring instrument has
   its own zero and is set up a little turned. The controller's settings
   are software and trusted exactly; the plant is not. These nuisance
   parameters — per axis the moving mass (known to :data:`NOMINAL_SPREAD`)
   and the viscous damping (to :data:`DAMPING_SPREAD`), a constant offset
   per axis and a small turn of the instrument's frame per pair of axes
   (free: a turn is not an out-of-squareness, which shears the frame) — act
   almost linearly on the trace. For an
   identified machine the controller is itself uncertain: one position-gain
   scale shared by all axes (a per-axis one would absorb a
   ``gain_mismatch``), likewise one velocity-feedforward fraction, and per
   axis the velocity-loop gain, each to :data:`NOMINAL_SPREAD`. Their
   sensitivities (one :func:`~contoursim.simulation.simulate_batch` call of
   finite differences; a step that makes a loop diverge is left out) are
   refitted in every residual below by ridge regression, a Gaussian prior
   centred on the nominal machine. How a given model's drives integrate in
   their velocity PI, where it does not say, is chosen by that refit
   (:func:`_integrator_chosen`).
   An effect is named only for what a slightly wrong nominal model cannot
   explain; once it is named, the nominal parameters are refitted by
   Gauss–Newton with it in place and its own parameters fitted again
   around them.
4. **Name**: every catalogue effect on every axis it can act on is a
   candidate. All candidates' starting grids run in one batch;
   the best row of each starts :func:`scipy.optimize.least_squares` (bounds
   from the catalogue) whose finite-difference Jacobian is one batch per
   iteration. Geometric candidates reuse the loop's axis positions (no
   re-simulation). Candidates are scored by the Bayesian information
   criterion of the whitened residual,
   ``ΔBIC = n_eff·ln(RSS_before/RSS_after) − k·ln(n_eff)``, where the
   residual is weighted by each axis's noise level (:func:`noise_level`,
   from the residual's second differences) and ``n_eff`` is the number of
   samples over the residual's integrated autocorrelation time (correlated
   model error counts for less than white noise). The best is accepted when
   ``ΔBIC > SIGNIFICANT`` (very strong evidence on the Kass–Raftery scale),
   still so fitted again on the plant refitted around it,
   and it closes at least :data:`GAP_SHARE` of the residual's power above
   the noise floor on the axes it acts on (where unmodelled dynamics
   dominate the residual, a catalogue effect bent to them is significant
   yet closes a sliver);
   the search repeats for a second and a third effect and stops when
   nothing is significant or, an effect named, the residual is at the noise floor
   (:data:`NOISE_FLOOR`). Two candidates within :data:`SIGNIFICANT` of each other are
   reported as ambiguous, with the test that would separate them, the more
   plausible named (a typical size; with a model, its controller as given:
   :func:`_choose`); so is a
   delay of an axis's position-loop reading (to first order a gain) that does
   not beat the gain mismatch of its axis as an effect is named (by
   ``SIGNIFICANT`` and :data:`GAP_SHARE` of what the gain leaves), and the
   gain is named.
"""

import copy
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import combinations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lombscargle, periodogram

from . import _validate
from ._parallel import fork_map
from .effects import Effect, effect_kind
from .exceptions import UnstableLoopError
from .identify import (SIGNIFICANT, _FEWEST_SAMPLES, _on_trace, autocorrelation_time, delta_bic,
                       identification_warnings, identify_machine, one_blas_thread)
from .kernel import MAX_DELAY_SAMPLES
from .machine import CONTROLLER_FIELDS
from .model import Model, as_model
from .output import json_text, strict
from .plotting import fit_circle_center
from .servo import VELOCITY_INTEGRATORS
from .simulation import measured_force, measured_reference, simulate_batch
from .traces import Trace

__all__ = [
    "DAMPING_SPREAD", "FIGURE_FILES", "GAP_SHARE", "MAX_EFFECTS", "NOISE_FLOOR", "NOMINAL_SPREAD", "REPORT_FORM", "REPORT_OPTIONAL", "SIGNIFICANT",
    "STRUCTURE_SHARE", "TIMING_SPREAD", "UNCERTAINTY_METHOD",
    "Diagnosis", "Step", "diagnose", "locate", "noise_level", "path_normal", "standstill_cycles", "turning", "unexplained",
    "within_noise", "plot_magnified", "plot_polar", "plot_residuals", "save_figures", "synthetic_trace",
]

#: Most effects named in one diagnosis.
MAX_EFFECTS = 3
#: How well the model times each axis's measured position (1σ, a fraction of the servo period): a simulation sampled
#: at the servo period and a continuous drive (its current loop, filters, the instant the logger reads the encoder)
#: differ by about that much, a few µs, too little to show in the residual, enough to move what a timing difference
#: of the axes fits as well (a one-way circle's squareness, a delay, a gain): the uncertainties are marginal over it.
TIMING_SPREAD = 0.01
#: How the reported uncertainties are obtained (the report's ``uncertainty_method``).
UNCERTAINTY_METHOD = ("the larger of the Gauss-Newton standard deviation (noise, scaled by the residual's "
                      "autocorrelation time; marginal over a time shift of each axis's measured position, known to "
                      f"{100 * TIMING_SPREAD:g} % of the servo period) and linearised block jackknives over 40, 20 "
                      "and 10 consecutive segments of the trace (model error that pulls the parameter differently "
                      "along the trace; the largest spread over the segment lengths), the mass, damping and instrument refit profiled out; for a "
                      "parameter the residual is jagged in at the finite-difference step (a backlash's lost motion "
                      "read on a scale), the fit, the residual and its derivative regressed over ±4 % of the "
                      "parameter's scale around it; added in "
                      "quadrature, how far the fit moved when the nominal parameters were refitted with the effect in "
                      "place (how much it hangs on a plant known only to its prior) and how far it moves when each "
                      "of the effect's parameters held at a default "
                      "(a vibration's mass ratio, a friction's Stribeck and viscous parts) lies elsewhere in its "
                      "typical range (by its RMS distance over that range)")
#: A residual share of at least this fraction of the noise level [-] is listed as unexplained structure.
STRUCTURE_SHARE = 0.5
#: With an effect named, the residual is at the noise floor when its RMS is within this factor of the noise estimated
#: from the trace: nothing more is named (a named effect's law, the catalogue's and not the machine's, leaves a misfit
#: of its own, which a second effect is bent to: a gain mismatch of 0.994 beside a delay, ΔBIC 38). With none named,
#: only at the noise itself: whether the nominal model lacks anything is the candidates' ΔBIC to say, which the noise
#: level's scale does not enter (a residual 2 % above the noise was an independent thermal drift, ΔBIC 1362).
NOISE_FLOOR = 1.1
#: An effect is named only when it closes at least this share of the residual's power above the noise floor on the
#: axes it acts on (RMS² − floor²): a significant fit that closes a sliver of a gap made by unmodelled dynamics is
#: not the missing effect.
GAP_SHARE = 0.25
#: The noise is the white part of the residual alone where the second differences' estimate exceeds it this many
#: times (:func:`noise_level`): white noise's two estimates agree within 6 % at 1000 samples, 59 % at 200.
LINE_RATIO = 2.0
#: How well a nominal servo parameter is known (1σ, relative): the prior of the nominal refit (for the moving
#: mass of a given model, and for every servo parameter of an identified one).
NOMINAL_SPREAD = 0.05
#: How well a given model's viscous damping is known (1σ, relative): guides and seals vary more than masses.
DAMPING_SPREAD = 0.2

_NUISANCE_STEP = 0.02  # relative step of the nominal parameters' finite differences
_FD_STEP = 1e-3  # relative step of the candidates' finite differences
_WIDE_STEP = 1e-2  # the secant that judges whether the residual is smooth at that step spans this share of the scale
_WIDE_POINTS = 4  # a rough parameter's residual is regressed over this many wide steps each side of the fit
_GRID = 4  # starting values per size parameter over its typical range (each sign)
_UM = 1e-3
_REFIT_STEPS = 2  # Gauss–Newton steps of the nominal refit once an effect is named
_MODE_DAMPING_MAX = 0.35  # largest damping ratio of a vibration candidate [-] (the catalogue's modes: 0.01–0.2)
# the uncertainty's block jackknife, blocking analysis: leaving out in turn each of this many consecutive segments of
# the trace, the largest spread (the estimate grows with the segments' length until they outlast the residual's
# correlations, and the fewer the segments the noisier it is: no one length is right for every trace)
_JACKKNIFE_BLOCKS = (40, 20, 10)
_PRIOR_REACH = 3.0  # prior widths a given model's plant moves at most before any effect is tried; moved further, it is said
_BACKTRACK = (1.0, 0.5, 0.25, 0.125)  # fractions of a nominal refit's Gauss–Newton step tried, the first that helps kept
_STEP_TOLERANCE = 0.01  # a nominal refit's Gauss–Newton step raising the residual's cost by more than this share is undone
# a refit whose current residual grows by more than this factor (and 1 % of the current's spread) departs from the
# measured current: said in a warning
_CURRENT_WORSE = 1.5
#: Effects whose named fit takes the measured current of their axis (``<axis>_current``) as a second output beside
#: the positions, with a given model: the force they put on the axis is what the current measures. The candidates
#: are told apart, and the plant refitted, by the positions alone: the current sees the drive's own dynamics (a
#: backlash's contacts ringing the screw) that no variant of the kernel follows sample by sample, and, whitened by
#: its noise, that misfit bent the fits it entered (as an output of every candidate's fit, an independent
#: backlash's lost motion came out 21 % off and a straightness was lost; in the plant's refit beside a friction,
#: the positions' misfit it left was named as a gain mismatch or a scale error: bench_diagnose, seeds 23 and 31).
CURRENT_FITS = ("coulomb_friction",)
_CURRENT_TOLERANCE = 1.25  # a friction fitted with the current leaves the positions at most this × their own fit's RMS
_CURRENT_SCALE = (0.0, 100.0)  # a measured current more than the first, less than the second times the model's is fitted
_WHITE_SAMPLES = 200  # fewer samples than this: the noise from the second differences alone (see LINE_RATIO)
_CYCLE_FALSE_ALARM = 1e-3  # share of white-noise standstill runs :func:`standstill_cycles` may take for a limit cycle
_SLOWEST_LOG = 0.01  # a trace sampled slower than this [s] does not resolve servo dynamics (a position loop's 1/kp)
_BOTH_WAYS = 0.25  # a trace runs its path both ways when at least this share of it turns each way [-]
_CONTENDERS = 3  # most candidates compared by their profile over the nominal parameters (:func:`_profiled`)
_CONTENDER_SHARE = 0.5  # ... each closing at least this share of what the best closes
_TWIN_SHARE = 0.8  # two candidates alike for a reason the trace cannot decide are twins when one closes this share of the other's gap
_BOW_BELOW = 4  # a straightness over the trace's own extent: grid steps below the typical peak (a guideway's, over
#                 its travel), down to 0.14 µm: the sag over a path a quarter of the travel is a sixteenth of it
_BOW_REACH = 5.0  # ... its vertex fitted within this many extents of the path's middle
_TWIN_RMS = 4.0  # ... and leaves at most this many times the other's residual RMS (whitened): beyond, the trace tells them
_REFIT_FIELDS = ("mass", "damping", "motor_mass", "screw_stiffness", "screw_damping_ratio") + CONTROLLER_FIELDS  # servo
# parameters the refit may move (the controller's if uncertain)
_SCREW_DAMPING_SPREAD = 0.5  # prior spread of a compliant screw's damping ratio [-, relative]: a data sheet guesses it
# what a candidate's simulation or fit may raise on a trace it cannot follow: the candidate is left out, not the run
_STABILISING = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)  # moves of one plant parameter tried on a loop the check refuses [prior widths]
_FIT_FAILURES = (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError)
_AS_WRITTEN = 1.1  # the corrected model as written leaving more than this × the last row's RMS is said
_REIDENTIFY = 2  # most times an identified machine's loops are identified again with the effects named held in place
_REIDENTIFY_GAP = 2.0  # ... when the diagnosis leaves more than this many noise levels (RMS) [-]
_REIDENTIFY_SHARE = 0.5  # ... kept when it closes this share of what was left above the noise floor (RMS² − floor²)
_HELD_SIZES = 4  # sizes over the typical range a friction or a delay is held at where nothing was named (_drive_held)
_HELD_PLAYS = 3  # ... and a backlash, each way it may be read
_HELD_MODES = 5  # frequencies over the typical range a structural mode is held at (_modes_held)
_HELD_SCREEN = 1.5  # ... the other sizes tried of a kind held at its middle leaving at most this × the least RMS there


def noise_level(residual, measured=None):
    """Measurement noise per axis, from the residual's high-frequency part [mm].

    ``σ = 1.4826·MAD(Δ²r)/√6``: the second difference removes the smooth
    part of the residual (model error), white noise of level σ gives
    ``var(Δ²r) = 6σ²``, and the median absolute deviation ignores the few
    samples at steps and spikes. A line in the spectrum near the Nyquist
    frequency (a limit cycle, a rattle, a mode) passes the second
    difference too, and is no noise: where the estimate exceeds
    :data:`LINE_RATIO` times that of the white part alone, the latter is
    taken: the median over the upper half of the band of the periodogram
    of Δr (Hann window) divided by the difference's gain ``4 sin²(πf)``,
    which for white noise is ``2σ²·ln 2`` (each bin a χ²₂), and which a few
    lines' bins do not move (for traces of more than 200 samples: with
    fewer, white noise alone exceeds the ratio by chance). A
    two-mass axis's rattle in its backlash, ±40 µm at 497 Hz logged at
    1 kHz, was a noise floor of 58 µm and left nothing to name.

    Positions logged with a resolution q (the smallest step between the
    values an axis takes, where it takes some value more than once: a log
    in steps of q; in a log of distinct values that smallest step is only
    how far the axis moved) carry at
    least the rounding noise ``q/√12``, which coarse logs hide from the
    second differences (most are zero).

    Parameters
    ----------
    residual : ndarray, shape (N, d)
        Measured minus simulated positions [mm].
    measured : ndarray, shape (N, d), optional
        The measured positions [mm], for their resolution.

    Returns
    -------
    ndarray, shape (d,)
        At least 1e-6 mm (1 nm).

    Raises
    ------
    ValueError
        `residual` is not 2-D, holds a non-finite value or fewer than 3
        samples; `measured` is not of its shape or not finite.
    """
    residual = _validate.finite_array("residual", residual, ndim=2)  # a NaN gave a NaN level, without a word
    if len(residual) < 3:
        raise ValueError(f"residual needs at least 3 samples (second differences), got {len(residual)}")
    if measured is not None:
        measured = _validate.finite_array("measured", measured, shape=residual.shape)
    d2 = np.diff(residual, n=2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    sigma = 1.4826 * mad / np.sqrt(6.0)
    if len(residual) > _WHITE_SAMPLES:
        f, power = periodogram(np.diff(residual, axis=0), window="hann", detrend="constant", axis=0)  # f [1/sample]
        upper = (f >= 0.25) & (f < 0.5)
        gain = 4.0 * np.sin(np.pi * f[upper]) ** 2  # the first difference's, |1 - exp(-2πif)|²
        white = np.sqrt(np.median(power[upper] / gain[:, None], axis=0) / (2 * np.log(2)))
        sigma = np.where(sigma > LINE_RATIO * white, white, sigma)
    if measured is not None:
        values = [np.unique(x) for x in measured.T]
        quantum = np.array([np.diff(v).min() if 1 < v.size < len(measured) else 0.0 for v in values])
        sigma = np.maximum(sigma, quantum / np.sqrt(12.0))
    return np.maximum(sigma, 1e-6)


@dataclass(frozen=True)
class Step:
    """One step of the diagnosis: the nominal model, its refit, or an effect named.

    Parameters
    ----------
    label : str
        ``"nominal model"``, ``"nominal refit"`` or the effect's ``name.axis``.
    effect : Effect or None
        The effect named at this step (``None`` for the nominal steps).
    uncertainty : dict
        One standard deviation of each fitted parameter [its unit].
    rms_um, max_um : float
        Residual RMS and max of the norm over axes after this step [µm].
    delta_bic : float
        ΔBIC of this step over the previous one (``nan`` for the nominal model).
    """

    label: str
    effect: object
    uncertainty: dict
    rms_um: float
    max_um: float
    delta_bic: float


#: The form of the report (:meth:`Diagnosis.to_dict`; :func:`contoursim.output.has_form`): ``diagnose --report``
#: replaces only a file of it.
REPORT_FORM = {"effects": ("name", "axis", "parameters"), "residual_rms_before_um": None,
               "residual_rms_after_um": None, "residual_max_before_um": None, "residual_max_after_um": None,
               "noise_um": None, "nominal_identified": None, "nominal_refit": None,
               "steps": ("label", "rms_um", "max_um"), "where": None, "warnings": None,
               "unexplained": ("signature", "rms_um"), "uncertainty_method": None}
#: The keys the report has besides those of :data:`REPORT_FORM`, some only where they apply: a file holding any other
#: (notes a user added to a report) is not replaced.
REPORT_OPTIONAL = ("zero_offset_um", "residual_normal_rms_before_um", "residual_normal_rms_after_um",
                   "current_residual_rms_before_A", "current_residual_rms_after_A")


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` found: the steps, the residuals before and after, where they were.

    Parameters
    ----------
    trace : contoursim.traces.Trace
        The measured trace.
    model : Model
        The nominal model (given, or identified: `identified`).
    identified : bool
        The nominal machine was identified from the trace.
    noise_um : ndarray, shape (d,)
        Measurement noise per axis [µm] (:func:`noise_level`).
    zero_um : ndarray, shape (d,)
        The zero taken out of each axis's measured positions [µm]: measured
        minus finally simulated, on average (an instrument's zero: a laser
        or a ballbar reads from where it was set; a millimetre is more
        likely a column from another axis or instrument).
    steps : tuple of Step
        The nominal model, its refit, then one step per effect named.
    simulated_before : ndarray, shape (N, d)
        The nominal model simulated on the measured reference [mm].
    simulated_after : ndarray, shape (N, d)
        The final model, nominal parameters refitted, at the trace's samples [mm].
    scored : ndarray of bool, shape (N,)
        The samples the fit scored (all but a start transient the simulation cannot reproduce).
    refitted : Model
        The final model: the nominal machine with its servo parameters refitted, its own effects and the effects named.
    where : tuple of str
        Where the nominal residual concentrates and what it correlates with (:func:`locate`).
    warnings : tuple of str
        Ambiguities (two candidates explaining the data almost equally, with
        the test that would separate them) and limits of the diagnosis.
    unexplained : tuple of dict
        Structure left in the final residual (:func:`unexplained`): per
        item ``axis``, ``signature`` (what it is: a limit cycle at
        standstill, a period, a correlation) and ``rms_um`` (its share of
        the residual [µm RMS]); never counted as noise.
    current_before, current_after : dict of str -> ndarray, shape (N,)
        For each axis whose current the trace measured, the current command
        of the nominal and of the final model at the trace's samples [A].
    """

    trace: object
    model: Model
    identified: bool
    noise_um: np.ndarray
    zero_um: np.ndarray
    steps: tuple
    simulated_before: np.ndarray
    simulated_after: np.ndarray
    scored: np.ndarray
    refitted: Model
    where: tuple = ()
    warnings: tuple = field(default=())
    unexplained: tuple = field(default=())
    current_before: dict = field(default_factory=dict)
    current_after: dict = field(default_factory=dict)

    @property
    def effects(self):
        """The effects named, in the order they were found."""
        return tuple(s.effect for s in self.steps if s.effect is not None)

    @property
    def residual_before(self):
        """Measured minus nominally simulated positions [mm], shape (N, d)."""
        return self.trace.actual - self.simulated_before

    @property
    def residual_after(self):
        """Measured minus finally simulated positions [mm], shape (N, d)."""
        return self.trace.actual - self.simulated_after

    def to_dict(self):
        """The report in the contract form (DESIGN.md), plus the story's details."""
        keep = self.scored
        before, after = self.residual_before[keep], self.residual_after[keep]
        normal_before, normal_after = (path_normal(self.trace.reference[keep], r) for r in (before, after))
        report = {
            "effects": [
                {"name": e.name, "axis": e.axis, "parameters": e.values(),
                 **({"options": dict(e.options)} if e.options else {}),
                 "uncertainty": dict(s.uncertainty),
                 "delta_bic": s.delta_bic}
                for s in self.steps for e in [s.effect] if e is not None
            ],
            "residual_rms_before_um": _rms_um(before),
            "residual_rms_after_um": _rms_um(after),
            "residual_max_before_um": _max_um(before),
            "residual_max_after_um": _max_um(after),
            "noise_um": {a: float(n) for a, n in zip(self.trace.axes, self.noise_um)},
            "zero_offset_um": {a: float(z) for a, z in zip(self.trace.axes, self.zero_um)},
            "nominal_identified": self.identified,
            "nominal_refit": {
                f"{axis}.{name}": {"nominal": getattr(servo, name), "refit": getattr(self.refitted.machine.axes[axis], name)}
                for axis, servo in self.model.machine.axes.items() for name in _REFIT_FIELDS
                if getattr(servo, name) != getattr(self.refitted.machine.axes[axis], name)
            },
            "steps": [{"label": s.label, "rms_um": s.rms_um, "max_um": s.max_um, "delta_bic": s.delta_bic}
                      for s in self.steps],
            "where": list(self.where),
            "warnings": list(self.warnings),
            "unexplained": [dict(u) for u in self.unexplained],
            "uncertainty_method": UNCERTAINTY_METHOD,
        }
        if normal_before is not None:
            report["residual_normal_rms_before_um"] = 1e3 * float(np.sqrt(np.mean(normal_before**2)))
            report["residual_normal_rms_after_um"] = 1e3 * float(np.sqrt(np.mean(normal_after**2)))
        if self.current_before:
            report["current_residual_rms_before_A"] = self.current_residual_rms(self.current_before)
            report["current_residual_rms_after_A"] = self.current_residual_rms(self.current_after)
        return strict(report)

    def current_residual_rms(self, simulated):
        """RMS of the measured minus the `simulated` current (:attr:`current_before` or `current_after`) on the
        scored samples, by axis [A]."""
        keep = self.scored
        return {a: float(np.sqrt(np.mean((self.trace.current[a][keep] - y[keep]) ** 2))) for a, y in simulated.items()}

    def to_json(self):
        """:meth:`to_dict` as strict JSON text (no NaN or Infinity: a value that is not finite is ``null``)."""
        return json_text(self.to_dict())

    def corrected_model(self, machine_file=None):
        """The corrected model as machine-file text: the refitted servo axes and the model's effects as ``[[effect]]`` tables.

        The effects are the nominal model's own (a machine file's
        ``[[effect]]`` tables, as given) followed by those named. Readable
        by :func:`contoursim.model.load_model` (``simulate``, ``compare``,
        ``diagnose --model``): identify on one experiment, validate on
        another.

        Parameters
        ----------
        machine_file : str or Path, optional
            The machine file (or preset name) the nominal model was read from:
            everything else it holds is carried over as it is (its geometry's
            ``[[body]]`` tables, an error table's file named where it lies).
            Needed for a machine with geometry.

        Returns
        -------
        str

        Raises
        ------
        ValueError
            The machine has geometry and no `machine_file` gives it.
        """
        from .config import TomlFile, toml_text
        from .machine import SERVO_KEYS, preset_file, tables_where_they_lie

        machine = self.refitted.machine
        if machine_file is None:
            if machine.chain is not None:
                raise ValueError("the nominal machine has geometry ([[body]] tables), which only its machine file holds: "
                                 "give machine_file")
            data = {"servo_period_ms": 1e3 * machine.servo_period, "axes": {}}
            if machine.max_feed is not None:
                data["max_feed_mm_min"] = 60.0 * machine.max_feed
        else:
            data = tables_where_they_lie(TomlFile.read(preset_file(machine_file)))  # not beside this text
        data["name"] = "corrected: " + machine.name
        keys = {name: key for key, name in SERVO_KEYS.items()}
        for axis, servo in machine.axes.items():
            table = data["axes"].setdefault(axis, {})
            for key, name in SERVO_KEYS.items():
                if getattr(servo, name) is None:
                    table.pop(key, None)
                else:
                    table[key] = getattr(servo, name)
            if machine_file is None and axis in machine.axis_travel:
                table["travel_mm"] = list(machine.axis_travel[axis])
            if machine_file is None and machine.uncertain.get(axis):
                table["uncertain"] = [keys[name] for name in machine.uncertain[axis]]
        data["effect"] = [{"name": e.name, "axis": e.axis, **e.values(), **e.options} for e in self.refitted.effects]
        if not data["effect"]:
            del data["effect"]
        source = self.trace.metadata.get("source", "")
        return ("# corrected model written by contoursim diagnose" + (f" from {source}" if source else "")
                + ": the nominal machine with its\n# plant refitted (see the report's nominal_refit), its own effects "
                "and the effects named as [[effect]] tables\n\n" + toml_text(data))

    def report(self):
        """The story as a short table: per step the effect, its parameters ± 1σ, residual RMS and max [µm]."""
        lines = [f"{'step':<28}{'parameters (± 1σ)':<52}{'RMS µm':>10}{'max µm':>10}{'ΔBIC':>10}", "-" * 110]
        for s in self.steps:
            if s.effect is None:
                text = ""
            else:
                default = {p.name: p.value for p in s.effect.kind.parameters}
                text = ", ".join(
                    f"{p.name} = {p.value:.4g}" + (f" ± {s.uncertainty[p.name]:.2g}" if p.name in s.uncertainty else "")
                    for p in s.effect.parameters if p.name in s.uncertainty or p.value != default[p.name]
                ) + "".join(f", {k} = {v}" for k, v in s.effect.set_options().items())
            bic = "" if np.isnan(s.delta_bic) else f"{s.delta_bic:.0f}"
            # a space before each column, however wide its value (a residual of metres on a trace in wrong units)
            lines.append(f"{s.label:<27} {text:<51} {s.rms_um:>9.3f} {s.max_um:>9.3f} {bic:>9}")
        noise = ", ".join(f"{a} {n:.3f}" for a, n in zip(self.trace.axes, self.noise_um))
        lines.append(f"noise floor [µm RMS]: {noise}")
        lines.append("instrument zero taken out [µm]: "  # a rounding's -0.0004 is +0.000, not -0.000
                     + ", ".join(f"{a} {round(z, 3) + 0.0:+.3f}" for a, z in zip(self.trace.axes, self.zero_um)))
        if self.current_before:
            before, after = self.current_residual_rms(self.current_before), self.current_residual_rms(self.current_after)
            lines.append("measured − simulated current [A RMS]: "
                         + ", ".join(f"{a} {before[a]:.4g} -> {after[a]:.4g}" for a in before))
        lines += [f"unexplained on {u['axis']}: {u['signature']} ({u['rms_um']:.3g} µm RMS)" for u in self.unexplained]
        if within_noise(self.effects, self.unexplained, self.steps[-1].rms_um, self.noise_um):
            lines.append("no effect named: the measurement is explained by the nominal model within noise "
                         "(and the nominal parameters' usual spread)")
        elif not self.effects:
            lines.append(f"no effect named: no catalogue effect explains the residual significantly; it stays at "
                         f"{self.steps[-1].rms_um:.3g} µm RMS against a noise floor of "
                         f"{float(np.linalg.norm(self.noise_um)):.3g} µm"
                         + (" (its structure: the 'unexplained' lines above)" if self.unexplained else ""))
        # where the nominal model's residual is, not the last row's (an effect named takes its part away)
        lines += [f"where (nominal model's residual): {w}" for w in self.where]
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _rms_um(r):
    return 1e3 * float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def _max_um(r):
    return 1e3 * float(np.max(np.linalg.norm(r, axis=1)))


def path_normal(reference, residual):
    """The residual's component along the path normal [mm], shape (N,); ``None`` for one axis.

    In the plane (2 axes) the signed component along the tangent turned by
    +90°; in space the magnitude of the part perpendicular to the tangent.
    The tangent is the commanded positions' central difference; where the
    reference stands still the whole residual counts.

    Parameters
    ----------
    reference : ndarray, shape (N, d)
        Commanded positions [mm].
    residual : ndarray, shape (N, d)
        Measured minus simulated positions [mm].

    Returns
    -------
    ndarray, shape (N,) or None
    """
    if reference.shape[1] < 2:
        return None
    tangent = np.gradient(reference, axis=0)
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    moving = norm[:, 0] > 1e-9 * max(float(norm.max()), 1e-300)
    tangent = np.where(moving[:, None], tangent / np.where(norm > 0, norm, 1.0), 0.0)
    if reference.shape[1] == 2:
        normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        return np.where(moving, np.sum(residual * normal, axis=1), np.linalg.norm(residual, axis=1))
    along = np.sum(residual * tangent, axis=1, keepdims=True)
    return np.linalg.norm(residual - along * tangent, axis=1)


# -- where the residual is ---------------------------------------------------------------------


def locate(trace, reference, residual):
    """Where a residual concentrates and what it correlates with, as sentences.

    Parameters
    ----------
    trace : contoursim.traces.Trace
    reference : contoursim.trajectory.Trajectory
        The measured reference at the servo period (for velocity and acceleration).
    residual : ndarray, shape (N, d)
        At the trace's samples [mm].

    Returns
    -------
    tuple of str
        The time spans (and path stations, the distance along the commanded
        path) holding most of it; for a circle test the angles of
        the largest radial residual (per direction where it is run both
        ways) and, run both ways, its oval per
        direction (:func:`_ovals`): the part keeping its orientation
        (geometric) and the part flipping (servo); per axis the features (reversals,
        velocity, acceleration, position, time, a spatial period) it
        correlates with best.
    """
    t = trace.t
    n = len(t)
    found = []
    energy = np.sum(residual**2, axis=1)
    if energy.sum() <= 0:
        return ()
    window = max(1, n // 200)
    smooth = np.convolve(energy, np.ones(window) / window, mode="same")
    hot = smooth > 0.25 * smooth.max()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hot.astype(int), [0]])))
    spans = sorted(((energy[a:b].sum() / energy.sum(), a, b) for a, b in zip(edges[::2], edges[1::2])), reverse=True)
    covered = sum(b - a for _, a, b in spans) / n
    station = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(trace.reference, axis=0), axis=1))])
    # 3 significant digits of the run's length: more on a clock that has run for days (t ~ 5e5 s), not '5e+05–5e+05 s'
    digits = 3 + max(0, int(np.floor(np.log10(max(abs(t[0]), abs(t[-1])) / max(t[-1] - t[0], 1e-300) + 1e-300))))
    text = ", ".join(f"{t[a]:.{digits}g}–{t[b - 1]:.{digits}g} s" + (f" (path station {station[a]:.4g}–{station[b - 1]:.4g} mm)"
                     if station[-1] > 0 else "") + f" ({100 * share:.0f} %)" for share, a, b in spans[:3])
    found.append(f"the residual energy concentrates in {text} ({100 * covered:.0f} % of the time)"
                 if covered < 0.5 else f"the residual is spread over the run (the largest part: {text})")
    circle = _circle(trace.reference)
    if circle is not None:
        center, radius = circle
        rel = trace.reference - center
        theta = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360
        radial = np.sum(residual[:, :2] * rel[:, :2], axis=1) / np.linalg.norm(rel[:, :2], axis=1)
    v = _on_trace(trace, reference.t, reference.velocity)
    a = _on_trace(trace, reference.t, reference.acceleration)
    if circle is not None:
        sense = np.sign(rel[:, 0] * v[:, 1] - rel[:, 1] * v[:, 0])
        # per 10° of angle, and per direction where the circle is run both ways (their mean would cancel a servo oval)
        bins = np.clip((theta // 10).astype(int), 0, 35)
        moving = sense[sense != 0]
        both = moving.size > 0 and min(np.mean(moving > 0), np.mean(moving < 0)) >= _BOTH_WAYS
        ways = ((sense > 0, " CCW"), (sense < 0, " CW")) if both else ((np.ones(len(t), bool), ""),)
        means = [(float(radial[way & (bins == k)].mean()), f"{10 * k + 5}°{label}") for way, label in ways
                 for k in range(36) if np.any(way & (bins == k))]
        found.append(f"circle R = {radius:.4g} mm: largest radial residual at " + ", ".join(
            f"{where} ({1e3 * mean:+.2f} µm)" for mean, where in sorted(means, key=lambda m: -abs(m[0]))[:3]))
        on = np.abs(np.linalg.norm(rel[:, :2], axis=1) - radius) < 1e-3 * radius
        ovals = _ovals(np.radians(theta[on]), radial[on], sense[on])
        if ovals is not None:
            ccw, cw = ovals
            keeps, flips = (ccw + cw) / 2, (ccw - cw) / 2
            angle = lambda c: np.degrees(np.angle(c)) / 2 % 180  # noqa: E731  major axis of A·cos(2(θ − φ))
            found.append(f"circle run both ways (ballbar): the oval (2θ term of the radial residual) {1e3 * abs(ccw):.3g} µm "
                         f"at {angle(ccw):.0f}° CCW, {1e3 * abs(cw):.3g} µm at {angle(cw):.0f}° CW: {1e3 * abs(keeps):.3g} µm "
                         f"keeps its orientation (geometric: squareness, scale), {1e3 * abs(flips):.3g} µm flips with the "
                         "direction (servo: a gain mismatch, a delay)")
    for i, axis in enumerate(trace.axes):
        r = residual[:, i] - residual[:, i].mean()
        if not np.any(r):
            continue
        since = _time_since_reversal(t, v[:, i])
        features = {
            "direction of motion (sign of v)": np.sign(v[:, i]),
            "reversals (first 50 ms after)": np.exp(-since / 0.05),
            "velocity": v[:, i],
            "acceleration": a[:, i],
            "position": trace.reference[:, i],
            "time": t,
        }
        scores = []
        for name, f in features.items():
            f = f - f.mean()
            target = np.abs(r) - np.abs(r).mean() if name.startswith("reversals") else r
            if np.ptp(f) > 0 and np.ptp(target) > 0:  # a constant (to its rounding) has none: corrcoef would divide by 0
                scores.append((abs(float(np.corrcoef(target, f)[0, 1])), name))
        period, share, _, _ = _spatial_period(trace.actual[:, i], r)
        if period is not None:
            scores.append((np.sqrt(share), f"a spatial period of {period:.3g} mm"))
        scores.sort(reverse=True)
        found.append(f"axis {axis}: correlates with " + ", ".join(f"{name} ({c:.2f})" for c, name in scores[:3]))
    return tuple(found)


def _ovals(theta, radial, sense):
    """The oval of a circle's radial residual run each way: the 2θ terms ``(CCW, CW)`` as complex amplitudes, or ``None``.

    ``radial ≈ c0 + c1·cos θ + s1·sin θ + Re(A·e^(−2iθ))`` fitted over the
    samples of each sense of motion (+1 CCW, −1 CW); ``None`` unless each
    holds at least :data:`_BOTH_WAYS` of them. ``A = c2 + i·s2`` [mm]: the
    oval's size |A| and its major axis at ``arg(A)/2``.
    """
    fits = []
    for way in (1.0, -1.0):
        mine = sense == way
        if mine.sum() < max(16, _BOTH_WAYS * sense.size):
            return None
        t = theta[mine]
        basis = np.column_stack([np.ones_like(t), np.cos(t), np.sin(t), np.cos(2 * t), np.sin(2 * t)])
        coef = np.linalg.lstsq(basis, radial[mine], rcond=None)[0]
        fits.append(complex(coef[3], coef[4]))
    return tuple(fits)


def _not_following(trace, simulated, scored):
    """Sentences for the axes whose measured positions do not follow their reference at all (empty when all do).

    An axis whose residual (measured − simulated, its mean removed) is as
    large as half its commanded motion is not a servo axis tracking its
    command with some error: its columns are swapped or in other units. Nor
    is one whose measured positions are its commanded ones to the last digit
    while it moves: no servo axis follows without a lag, that is one signal
    logged twice.
    """
    found = []
    for i, axis in enumerate(trace.axes):
        ref = trace.reference[scored, i]
        motion = float(np.std(ref))
        if motion > 0 and np.array_equal(trace.actual[scored, i], ref):
            found.append(f"the measured {axis} is {axis}_ref to the last digit on every sample while it moves (the model "
                         f"lags by up to {1e3 * np.abs(simulated[scored, i] - ref).max():.4g} µm): the command logged "
                         "twice? No effect is named")
            continue
        miss = float(np.std(trace.actual[scored, i] - simulated[scored, i]))
        if motion > 0 and miss > 0.5 * motion:
            found.append(f"the measured {axis} does not follow {axis}_ref (the residual, {1e3 * miss:.4g} µm RMS, is "
                         f"as large as the commanded motion, {1e3 * motion:.4g} µm RMS): columns swapped or units "
                         "wrong? No effect is named")
    return found


def _leading(trace, simulated, scored, noise):
    """Sentences for the axes whose measured positions lead their reference by about the lag the model has them behind.

    A servo axis lags its command by a time, its position behind by that time
    of travel (v/kp without feedforward). Measured minus commanded positions
    that lead by more than half of the lag the model has the axis behind
    (each regressed on the commanded velocity: a time, negative behind; the
    model's lag clear of the noise) are a trace whose columns are swapped.
    Where the model does not have the axis behind (velocity feedforward
    leaves a lag of either sign, little of it in proportion to the speed), a
    measured lag tells nothing of the columns: an axis behind its command by
    a delay the model lacks is no swap.
    """
    found = []
    for i, axis in enumerate(trace.axes):
        v = np.gradient(trace.reference[:, i], trace.t)[scored]
        v = v - v.mean()
        speed = float(v @ v)
        if speed == 0.0:
            continue
        behind, seen = ((y[scored, i] - trace.reference[scored, i]) @ v / speed for y in (simulated, trace.actual))  # [s]
        if -behind * np.sqrt(speed / v.size) > 3 * noise[i] and seen > -0.5 * behind:
            found.append(f"the measured {axis} leads {axis}_ref by {seen / -behind:.2f} times the lag the model has it "
                         f"behind ({-1e3 * behind:.3g} ms of travel; a servo axis follows its command, it does not "
                         f"anticipate it): are {axis} and {axis}_ref swapped? No effect is named")
    return found


def standstill_cycles(trace, reference, residual, min_samples=64):
    """Limit cycles at standstill ("hunting"): per axis, oscillation in one narrow band while the reference stands still.

    Over the second half of every run of at least `min_samples` samples in
    which no axis's reference moves (the first half may still be settling),
    the residual (linear trend removed, Hann window) is a limit cycle when
    one spectral line, at three or more periods per run, holds at least
    half of its variance: white noise spreads over all frequencies. Over a
    short run it spreads over few, and the share white noise reaches once
    in :data:`_CYCLE_FALSE_ALARM` runs is asked for if more
    (:func:`_cycle_share`): of 33 samples' 17 lines, five held half the
    variance of one run of white noise in three. The measured position
    itself must turn back and forth over those periods: a position that
    only creeps one way, rounded to its counts, leaves a residual sawtooth
    of one line too.

    Parameters
    ----------
    trace : contoursim.traces.Trace
    reference : contoursim.trajectory.Trajectory
        The measured reference at the servo period.
    residual : ndarray, shape (N, d)
        At the trace's samples [mm].
    min_samples : int
        Shortest standstill run looked at.

    Returns
    -------
    dict
        Axis index -> ``{"samples": bool mask (N,) of the cycling samples,
        "frequency": [Hz], "amplitude": half the peak-to-peak of the cycle [mm]}``.
    """
    v = _on_trace(trace, reference.t, reference.velocity)
    speed = np.linalg.norm(v, axis=1)
    still = speed <= 1e-9 * max(float(speed.max()), 1e-300) if speed.max() > 0 else np.ones(len(speed), bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    runs = [(a + (b - a) // 2, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_samples]
    found = {}
    for i in range(residual.shape[1]):
        mask = np.zeros(len(speed), bool)
        freqs, amps = [], []
        for a, b in runs:
            x = residual[a:b, i]
            n = len(x)
            x = x - np.polyval(np.polyfit(np.arange(n), x, 1), np.arange(n))
            spec = np.abs(np.fft.rfft(x * np.hanning(n))) ** 2
            spec[0] = 0.0
            if spec.sum() <= 0:
                continue
            k = int(np.argmax(spec))
            if (k >= 3 and spec[max(k - 2, 1):k + 3].sum() >= _cycle_share(n) * spec.sum()
                    and _turns(trace.actual[a:b, i]) >= 2 * 3):
                mask[a:b] = True
                freqs.append(k / (n * trace.dt))
                amps.append(0.5 * float(np.ptp(x)))
        if mask.sum() >= min_samples // 2:
            found[i] = {"samples": mask, "frequency": float(np.median(freqs)), "amplitude": float(np.median(amps))}
    return found


def _turns(x):
    """How many times the position `x` turns back (a machine that hunts turns twice a cycle)."""
    steps = np.diff(x)
    steps = np.sign(steps[steps != 0])
    return int(np.count_nonzero(steps[1:] != steps[:-1]))


@lru_cache(maxsize=None)
def _cycle_share(n):
    """The share of a run's variance the band of :func:`standstill_cycles` must hold in a run of `n` samples: half,
    or what the band's share of white noise reaches once in :data:`_CYCLE_FALSE_ALARM` runs if more (Monte Carlo,
    4/α runs, a fixed seed). From about 80 samples on that is less than half (0.41 at 100): not computed."""
    if n >= 128:
        return 0.5
    x = np.random.default_rng(n).standard_normal((int(4 / _CYCLE_FALSE_ALARM), n))
    i = np.arange(n)
    x -= np.polynomial.polynomial.polyfit(i, x.T, 1).T @ np.vstack([np.ones(n), i])  # each run's trend removed
    spec = np.abs(np.fft.rfft(x * np.hanning(n), axis=1)) ** 2
    spec[:, 0] = 0.0
    k = np.argmax(spec, axis=1)
    total = np.concatenate([np.zeros((len(x), 1)), np.cumsum(spec, axis=1)], axis=1)
    rows = np.arange(len(x))
    band = total[rows, np.minimum(k + 3, spec.shape[1])] - total[rows, np.maximum(k - 2, 1)]
    share = np.where(k >= 3, band / total[:, -1], 0.0)
    return max(0.5, float(np.quantile(share, 1.0 - _CYCLE_FALSE_ALARM)))


def within_noise(effects, unexplained, rms_um, noise_um):
    """Whether a diagnosis explains the measurement by the nominal model within noise: no effect named, no structure
    left unexplained, and a residual within :data:`NOISE_FLOOR` times the noise level.

    Parameters
    ----------
    effects, unexplained : sequence
        The effects named and the structure left (:class:`Diagnosis`'s, or its report's lists).
    rms_um : float
        The final residual [µm RMS].
    noise_um : sequence of float
        The noise level per axis [µm].

    Returns
    -------
    bool
    """
    return not effects and not unexplained and rms_um <= NOISE_FLOOR * float(np.linalg.norm(noise_um))


def unexplained(trace, reference, residual, noise, scored):
    """Structure left in a residual: what is not white noise, as ``{"axis", "signature", "rms_um"}`` items.

    Per axis, each of these is listed when its share of the residual (the
    RMS of the residual's projection on it) reaches :data:`STRUCTURE_SHARE`
    times the axis's noise level: a limit cycle at standstill
    (:func:`standstill_cycles`), the largest spectral line, and a
    correlation with the commanded velocity, acceleration, direction of
    motion, position or time (the sign of the correlation coefficient given).
    A residual above :data:`NOISE_FLOOR` times the noise level that none of
    these accounts for (their shares together under half of what lies
    beyond the noise) is listed all the same, as what lies beyond the
    noise, with where its power is: concentrated where the command
    accelerates, or spread over the run. Nothing above the noise is left
    unsaid.

    Parameters
    ----------
    trace : contoursim.traces.Trace
    reference : contoursim.trajectory.Trajectory
        The measured reference at the servo period.
    residual : ndarray, shape (N, d)
        The final residual at the trace's samples [mm] (0 where not scored).
    noise : ndarray, shape (d,)
        The white noise level per axis [mm] (:func:`noise_level`).
    scored : ndarray of bool, shape (N,)

    Returns
    -------
    list of dict
        ``rms_um`` [µm], largest first per axis.
    """
    found = []
    v = _on_trace(trace, reference.t, reference.velocity)[scored]
    acc = _on_trace(trace, reference.t, reference.acceleration)[scored]
    cycles = standstill_cycles(trace, reference, residual)
    for i, axis in enumerate(trace.axes):
        r = residual[scored, i] - residual[scored, i].mean()
        n = r.size
        if n < 16 or not np.any(r):
            continue
        share = STRUCTURE_SHARE * noise[i]
        items = []
        if i in cycles:
            c = cycles[i]
            items.append((float(np.sqrt(np.mean(residual[c["samples"], i] ** 2))),
                          f"limit cycle at standstill (hunting): ±{1e3 * c['amplitude']:.3g} µm at {c['frequency']:.3g} Hz"))
        spec = np.abs(np.fft.rfft(r)) ** 2
        spec[0] = 0.0
        k = int(np.argmax(spec))
        line = float(np.sqrt(2.0 * spec[max(k - 1, 1):k + 2].sum()) / n)  # RMS of the line (±1 bin)
        if k >= 2 and spec[max(k - 1, 1):k + 2].sum() >= 0.2 * spec.sum():
            items.append((line, f"periodic, {k / (n * trace.dt):.3g} Hz"))
        features = {"velocity": v[:, i], "acceleration": acc[:, i], "direction of motion (sign of v)": np.sign(v[:, i]),
                    "position": trace.reference[scored, i], "time (a drift)": trace.t[scored]}
        for name, f in features.items():
            f = f - f.mean()
            if not np.any(f):
                continue
            rho = float(np.dot(r, f) / (np.linalg.norm(r) * np.linalg.norm(f)))
            if abs(rho) >= 0.3:
                items.append((abs(rho) * float(np.sqrt(np.mean(r**2))), f"correlated with {name} (r = {rho:+.2f})"))
        items = [(rms, signature) for rms, signature in sorted(items, reverse=True) if rms >= share]
        total = float(np.sqrt(np.mean(r**2)))
        beyond = float(np.sqrt(max(total**2 - noise[i] ** 2, 0.0)))
        if total > NOISE_FLOOR * noise[i] and np.hypot.reduce([rms for rms, _ in items] or [0.0]) < 0.5 * beyond:
            items.append((beyond, f"beyond the white noise ({1e3 * noise[i]:.3g} µm) and matching no signature: "
                                  + _where_power_is(r, acc[:, i])))
        found += [{"axis": axis, "signature": signature, "rms_um": 1e3 * rms} for rms, signature in items]
    return found


def _where_power_is(r, acc):
    """Where a residual's power lies in words: concentrated where the command accelerates, or spread over the run."""
    moving = np.abs(acc) > 0.1 * np.abs(acc).max() if np.any(acc) else np.zeros(r.size, bool)
    samples, power = moving.mean(), float(np.sum(r[moving] ** 2) / np.sum(r**2))
    if 0.0 < samples < 0.5 and power >= max(0.5, 2.0 * samples):  # at least half its power, twice its share of time
        return (f"concentrated where the command accelerates ({100 * power:.0f} % of its power in the "
                f"{100 * samples:.0f} % of the samples), dynamics the model lacks")
    return "spread over the run"


def _circle(position):
    """``(centre, radius)`` when most of the first two axes' reference runs one full circle, else ``None``.

    The circle is fitted (algebraically) to the points near it, narrowing
    from 20 % to 0.03 % of the radius, so that run-in and run-out arcs or
    approach moves do not pull it; half the samples must lie on it.
    """
    if position.shape[1] < 2:
        return None
    p = position[:, :2]
    on = np.ones(len(p), bool)
    for tol in (np.inf, 0.2, 0.05, 0.01, 1e-3, 3e-4):
        if on.sum() < 3:
            return None
        center = fit_circle_center(p[on])
        r = np.linalg.norm(p - center, axis=1)
        radius = float(np.median(r[on]))
        on = np.abs(r - radius) < tol * radius
    if radius <= 0 or on.mean() < 0.5:
        return None
    rel = p[on] - center
    angle = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    if np.ptp(angle) < 2 * np.pi * 0.95:
        return None
    return np.concatenate([center, np.zeros(position.shape[1] - 2)]), radius


def _time_since_reversal(t, v):
    """Time since the last sign change of `v` [s] (since the start before the first)."""
    s = np.sign(v)
    moving = np.flatnonzero(s)
    since = t - t[0]
    if moving.size < 2:
        return since
    flips = moving[1:][s[moving[1:]] != s[moving[:-1]]]
    last = np.full(len(t), t[0])
    last[flips] = t[flips]
    return t - np.maximum.accumulate(last)


def _spatial_period(q, r):
    """The spatial period [mm] best explaining `r` over position `q`, the share of the variance it explains, and
    the sinusoid's amplitude [mm] and phase [deg] at that period (``amplitude·sin(2π·q/period + phase)``).

    The Lomb–Scargle periodogram of `r` over `q` (unevenly sampled: the axis
    moves back and forth, dwells and crosses its stroke at varying speed),
    from one period over the stroke to 200 (and none shorter than 0.5 mm),
    four frequencies per resolution step ``1/stroke``, scanned on the
    samples' means over bins of a sixteenth of the shortest period, weighted
    by their counts (a peak attenuated by under 1 %; 2–3 times faster on
    7,000–8,000 samples, 7 times on 30,000), the peak then refined on the samples
    on a grid of a hundredth of a cycle over the stroke and between its lines
    (a phase drift of a few degrees from one end to the other: the
    sinusoid's amplitude and phase then mean what they say, a start the fit
    need not walk from).
    """
    travel = float(np.ptp(q))
    if travel <= 1.0:
        return None, 0.0, 0.0, 0.0
    cycles = np.arange(1.0, min(200.0, 2.0 * travel) + 1e-9, 0.25)  # periods over the stroke
    bins = np.minimum(((q - q.min()) * (16.0 * cycles[-1] / travel)).astype(int), int(16.0 * cycles[-1]) - 1)
    counts = np.bincount(bins)
    held = counts > 0
    means = [np.bincount(bins, v)[held] / counts[held] for v in (q, r)]
    power = lombscargle(*means, 2 * np.pi * cycles / travel, floating_mean=True, weights=counts[held].astype(float))
    fine = cycles[np.argmax(power)] + np.linspace(-0.25, 0.25, 51)
    fine = fine[fine >= 1.0]
    power = lombscargle(q, r, 2 * np.pi * fine / travel, floating_mean=True)
    k = int(np.argmax(power))
    vertex = 0.0  # the peak's vertex between grid lines (a parabola through three), where the peak has both
    if 0 < k < fine.size - 1:
        below, peak, above = power[k - 1 : k + 2]
        bend = below - 2.0 * peak + above
        vertex = 0.5 * (below - above) / bend if bend < 0 else 0.0
    period = travel / float(fine[k] + vertex * (fine[1] - fine[0]))
    w = 2 * np.pi * q / period
    basis = np.column_stack([np.sin(w), np.cos(w)])
    (s, c) = coef = np.linalg.lstsq(basis, r, rcond=None)[0]
    share = float(np.sum((basis @ coef) ** 2)) / float(r @ r)
    return period, share, float(np.hypot(s, c)), float(np.degrees(np.arctan2(c, s)))


# -- the fit -----------------------------------------------------------------------------------


class _Problem:
    """A measured trace against variants of one model: predictions, whitening, nominal refit.

    The fit's outputs are the tool positions of the trace's axes (d
    columns), then, while :meth:`use_currents` has them on, the current of
    each axis in `current_noise` (c columns, whitened by its noise [A]).
    An output array here is (N, d + c); :meth:`fitted` and :meth:`unwhiten`
    give the positions alone.
    """

    def __init__(self, trace, model, noise, scored, identified=False, force=None, current_noise=None,
                 refit=_REFIT_STEPS):
        self.trace = trace
        self.identified = identified  # the controller too was identified: its parameters carry the prior
        self.reference = measured_reference(trace, model.machine.servo_period)
        self.force = force or {}  # the known external forces on the reference's samples [N], by axis
        self.scored = scored  # samples the fit scores, shape (N,)
        self.noise = noise  # the positions' [mm], shape (d,)
        self.current_noise = current_noise or {}  # the measured currents' the fit may take as outputs [A], by axis
        self.nominal = model.machine  # the prior of the nominal refit is centred here
        self.base = None
        self._outputs(())
        self.set_base(model, refit=refit, reach=np.inf if identified else _PRIOR_REACH)

    def _outputs(self, currents):
        """Fit the positions and the measured currents of the axes `currents`."""
        self.currents = list(currents)
        self.measured = np.column_stack([self.trace.actual] + [self.trace.current[a] for a in self.currents])
        sigma = np.concatenate([self.noise, [self.current_noise[a] for a in self.currents]])
        self.weight = self.scored[:, None] / sigma  # 1/σ per output on scored samples, 0 elsewhere [1/mm, 1/A]
        self.n = int(self.scored.sum()) * len(sigma)  # residual entries scored

    def use_currents(self, on):
        """Take the measured currents (of :attr:`current_noise`) as outputs beside the positions, or not: the base
        linearised again for them."""
        currents = list(self.current_noise) if on else []
        if currents != self.currents:
            self._outputs(currents)
            self._linearise(self.base)

    # predictions at the trace's samples
    def predict(self, models):
        """The outputs of `models` at the trace's samples (tool positions, then the currents fitted), list of (N, d + c)."""
        out = []
        loop = [m for m in models if not self._geometric_only(m)]
        for start in range(0, len(loop), 64):
            runs = self._run(loop[start : start + 64], ("tool_position",))
            out += [_on_trace(self.trace, self.reference.t, y) for y in runs["outputs"]]
        loop_results = iter(out)
        results = []
        for m in models:
            if self._geometric_only(m):  # the loop is the base's: its currents too
                y = m.geometry.tool_position(self.axis_position, self.reference.t, self.trace.reference.shape[1])
                d = y.shape[1]
                results.append(np.column_stack([_on_trace(self.trace, self.reference.t, y),
                                                self.base_prediction[:, d:]]))
            else:
                results.append(next(loop_results))
        return results

    def _run(self, models, outputs):
        """:func:`simulate_batch` of `models` with `outputs`, and under ``"outputs"`` the fit's outputs on the
        servo grid: the tool positions, then the currents of the axes in :attr:`currents`, shape (B, M, d + c)."""
        run = simulate_batch(models, self.reference, outputs=outputs + (("current",) if self.currents else ()),
                             settle=0.0, check=False, force=self.force)
        names = list(models[0].machine.axes)
        currents = [run["current"][:, :, [names.index(a) for a in self.currents]]] if self.currents else []
        run["outputs"] = np.concatenate([run["tool_position"]] + currents, axis=2)
        return run

    def _geometric_only(self, model):
        """`model` differs from the base in geometric effects only (the loop's axis positions can be reused)."""
        if self.base is None:
            return False
        other = [e for e in model.effects if e.stage != "geometry"]
        return model.machine is self.base.machine and other == [e for e in self.base.effects if e.stage != "geometry"]

    def whitened(self, y):
        """``(measured − y)/σ`` per output, flattened, shape (N·(d + c),)."""
        return ((self.measured - y) * self.weight).ravel()

    def coefficients(self, r):
        """The nominal refit of a whitened residual `r`: zero offsets [steps of σ], the instrument frame's turn per
        pair of axes [rad], then each nominal step's factor."""
        return self.solve @ r - self.pull

    def residual(self, y):
        """The residual of prediction `y` after the nominal refit: whitened misfit, then the prior's terms.

        Shape (N·(d + c) + I + K,): what the refit leaves of the whitened residual,
        then the refit's coefficients over their prior widths (a nominal
        parameter is known to its spread; the instrument's I columns, its
        zero per axis and the turn of its frame per pair of axes, are free).
        """
        with np.errstate(over="ignore", invalid="ignore"):  # a variant that went unstable: made large by _finite
            r = self.whitened(y)
            c = self.coefficients(r)
            return np.concatenate([r - self.columns @ c, self.prior * (c + self.shift)])

    def samples(self, r):
        """The misfit part of a :meth:`residual`, per sample, shape (N, d + c)."""
        n, w = self.measured.shape
        return r[: n * w].reshape(n, w)

    def set_base(self, model, refit=0, reach=np.inf, free=()):
        """Make `model` the base: its prediction, axis positions and the nominal refit's sensitivities.

        With `refit` > 0, up to that many Gauss–Newton steps first move the
        base's nominal parameters to their (prior-weighted) least-squares
        values, the linearised refit then handling only what is left. A step
        is kept unless it raises the residual (:meth:`residual`, its linearised
        refit included) by more than :data:`_STEP_TOLERANCE`: within reach of
        the linearisation the new base's residual is the old one's but for
        second-order terms; where the trace's dynamics lie beyond it (a plant
        the model lacks, a loop near its stability edge), a full step can
        overshoot: it is shortened by the fractions of :data:`_BACKTRACK`, and
        where none helps the base stays where it was. On an identified
        machine a step to loops the loop check refuses (a velocity gain
        pushed past a quarter of the Nyquist frequency, beyond what the
        identification allows) is shortened likewise. A given model's plant
        follows the trace there (a machine may run with less margin than the
        check asks): the report says so.

        With `reach`, no step takes a nominal parameter further than that many
        prior widths from the nominal machine, but for the parameters of the
        axes in `free`. The first refit of a given
        model, before any effect is tried, stops at :data:`_PRIOR_REACH` (an
        identified one is the trace's own fit): a plant pulled further
        is taking up something the model lacks, and bent there it would hide
        that effect from the candidates screened against it (a two-mass axis's
        backlash of 7.4 µm bent its mass from 486 to 246 kg, leaving 1.95 µm
        that no candidate explained). The refit with effects in place goes as
        far as the trace pulls it on the axes they act on (:func:`_reach`),
        with none found on every axis.
        """
        free = set(free)
        self._linearise(model)
        for _ in range(refit):
            if not self.changes:
                break
            coef = self.coefficients(self.whitened(self.base_prediction))[self.instrument:]
            if not np.all(np.isfinite(coef)):
                break
            widths, shift = self.prior[self.instrument:], self.shift[self.instrument:]  # per step; steps from nominal
            limit = np.array([np.inf if free.intersection(change) else reach for change, _ in self.changes])
            coef = np.clip((coef + shift) * widths, -limit, limit) / widths - shift
            cost = float(self.base_residual @ self.base_residual)
            changes = [change for change, _ in self.changes]
            for fraction in _BACKTRACK:
                trial = _refitted(model, changes, coef, fraction)
                if self.identified and trial.machine.refusal(self.trace.axes):
                    continue  # an identified loop beyond what identification allows, which simulate would refuse
                self._linearise(trial)
                with np.errstate(over="ignore"):  # a trial whose loop runs away: an infinite cost, refused
                    worse = not float(self.base_residual @ self.base_residual) <= (1.0 + _STEP_TOLERANCE) * cost
                if not worse:
                    break
            else:
                self._linearise(model)  # every fraction of the step made it worse (or the loop diverge): the last base
                break
            model = trial

    def _linearise(self, model):
        self.base = None
        run = self._run([model], ("tool_position", "axis_position"))
        self.axis_position = run["axis_position"][0]
        self.base_prediction = _on_trace(self.trace, self.reference.t, run["outputs"][0])
        self.changes = _nuisance_changes(model, self.trace.axes, self.identified)
        n, w = self.measured.shape
        d = self.trace.actual.shape[1]
        # instrument zero per axis's position (a current's offset is a force, which the candidates stand for)
        columns = [(np.eye(w)[i] * self.weight).ravel() for i in range(d)]
        q = self.trace.reference - self.trace.reference[self.scored].mean(axis=0)
        for i, j in combinations(range(d), 2):  # the instrument's frame turned a little in the plane of axes i, j
            turn = np.zeros((n, w))
            turn[:, i], turn[:, j] = -q[:, j], q[:, i]
            if np.ptp(q[self.scored][:, [i, j]], axis=0).max() > 1e-9:  # two axes that stand still have no frame to
                # turn (centred by a mean's rounding, their 35 mm left 1e-14 mm: a column the zeros' own, singular)
                columns.append((turn * self.weight).ravel())
        self.instrument = len(columns)  # the instrument's columns (zero and alignment), free
        if self.changes:
            ys = self.predict([_with_servos(model, change) for change, _ in self.changes])
            r0 = self.whitened(self.base_prediction)
            # a step that makes the loop diverge is left out: its prediction is not finite or, growing slowly,
            # moves further from the base's than the trace moves at all (no sensitivity of a 2 % step does)
            reach = max(float(np.ptp(self.trace.actual)), 1.0)
            with np.errstate(invalid="ignore", over="ignore"):
                kept = [bool(np.all(np.abs(y - self.base_prediction)[:, :d] <= reach)) for y in ys]
            self.changes = [c for c, ok in zip(self.changes, kept) if ok]
            columns += [r0 - self.whitened(y) for y, ok in zip(ys, kept) if ok]  # each nominal step's effect, whitened
        s = self.columns = np.column_stack(columns)
        self.prior = np.concatenate([np.zeros(self.instrument), [_NUISANCE_STEP / spread for _, spread in self.changes]])
        # ridge: the prior on the nominal parameters, centred on the nominal machine (the base may have moved from it)
        self.shift = np.concatenate([np.zeros(self.instrument),
                                     [_steps_from(self.nominal, model.machine, c) for c, _ in self.changes]])
        normal = s.T @ s + np.diag(self.prior**2)
        self.solve = np.linalg.solve(normal, s.T)
        self.pull = np.linalg.solve(normal, self.prior**2 * self.shift)
        self.base = model
        self.base_residual = self.residual(self.base_prediction)

    def zero_offset(self):
        """The instrument zero of each axis the nominal refit finds [mm], shape (d,)."""
        d = self.trace.actual.shape[1]
        return self.coefficients(self.whitened(self.base_prediction))[:d]

    def fitted(self):
        """The base's tool positions with the nominal refit (and instrument zero) added [mm], shape (N, d)."""
        r = self.whitened(self.base_prediction)
        d = self.trace.actual.shape[1]
        return self.base_prediction[:, :d] + self.unwhiten(self.columns @ self.coefficients(r))

    def left(self):
        """What the base (its nominal refit and instrument zero included) leaves of the measured positions on the
        scored samples [mm], shape (n, d)."""
        return (self.trace.actual - self.fitted())[self.scored]

    def as_written(self):
        """What the base itself leaves of the measured positions on the scored samples [mm], shape (n, d): the
        instrument's zero and turn fitted, not the linearised refit of its plant (:meth:`left` adds it)."""
        r = self.whitened(self.base_prediction)
        own = self.columns[:, : self.instrument]
        return self.unwhiten(r - own @ np.linalg.lstsq(own, r, rcond=None)[0])[self.scored]

    def unwhiten(self, r):
        """The positions' part of a whitened vector (its first N·(d + c) entries) [mm], shape (N, d); 0 on samples
        not scored."""
        d = self.trace.actual.shape[1]
        weight = self.weight[:, :d]
        return np.divide(self.samples(r)[:, :d], weight, out=np.zeros(weight.shape), where=weight > 0)


def _nuisance_changes(model, axes, identified):
    """The nominal refit's steps: ``({axis: {field: stepped value}}, prior spread)`` per nominal parameter of `axes`.

    A given model's controller (gains, integral time, feedforward, period) is
    software, set exactly: only the plant carries a prior, the moving mass
    (with the force constant fixed, it sets the velocity loop's gain and
    the acceleration feedforward's match), the viscous damping, a compliant
    screw's motor-side mass, stiffness and damping ratio, and the
    controller settings the machine file lists as ``uncertain``. An
    identified controller is itself uncertain: one position gain and one
    feedforward fraction for all axes, the velocity gain per axis.
    """
    servos = model.machine.axes
    h = 1.0 + _NUISANCE_STEP
    changes = []
    if not identified:
        for a in axes:
            s = servos[a]
            changes.append(({a: {"mass": s.mass * h}}, NOMINAL_SPREAD))
            if s.damping > 0:
                changes.append(({a: {"damping": s.damping * h}}, DAMPING_SPREAD))
            if s.compliant:  # the screw: its motor side's mass and stiffness as a data sheet gives them, its damping guessed
                changes += [({a: {"motor_mass": s.motor_mass * h}}, NOMINAL_SPREAD),
                            ({a: {"screw_stiffness": s.screw_stiffness * h}}, NOMINAL_SPREAD),
                            ({a: {"screw_damping_ratio": s.screw_damping_ratio * h}}, _SCREW_DAMPING_SPREAD)]
            for name in model.machine.uncertain.get(a, ()):  # settings the machine file marks as not known exactly
                value = getattr(s, name)
                stepped = value * h if name not in ("vff", "aff") or value * h <= 1 else value / h
                changes.append(({a: {name: stepped}}, NOMINAL_SPREAD))
        return changes
    changes.append(({a: {"kp": s.kp * h} for a, s in servos.items()}, NOMINAL_SPREAD))  # one position gain for all axes
    feedforward = {a: {"vff": s.vff * h if s.vff * h <= 1 else s.vff / h} for a, s in servos.items() if s.vff > 0}
    if feedforward:  # one fraction for all axes too: per axis it would set each axis's steady lag, a gain in disguise
        changes.append((feedforward, NOMINAL_SPREAD))
    for a in axes:
        s = servos[a]
        changes.append(({a: {"kv": s.kv * h}}, NOMINAL_SPREAD))  # the velocity loop's gain over the mass: its bandwidth
        if s.damping > 0:
            changes.append(({a: {"damping": s.damping * h}}, DAMPING_SPREAD))
        if s.aff > 0:
            changes.append(({a: {"mass": s.mass * h}}, NOMINAL_SPREAD))
    return changes


def _stable_start(model, axes):
    """Where the loop check refuses an axis of a given model, the nearest plant within its prior that it accepts.

    A data sheet may describe a machine commissioned at its stability edge
    that the check refuses (a screw's damping guessed, a mass a few % off)
    while the measured trace shows the machine stable: the trace is the
    judge. On each refused axis one plant parameter of the nominal refit
    (:func:`_nuisance_changes`) moves by the fewest prior widths of
    :data:`_STABILISING` (the largest gain margin among equals) to where the
    check passes; the diagnosis starts there (its prior centred there too).

    Returns
    -------
    (Model, list of str)
        The model to start from (`model` when the check accepts every axis)
        and one warning per moved axis.

    Raises
    ------
    UnstableLoopError
        No such move makes an axis's loop pass the check (the check's message).
    """
    dt = model.machine.servo_period
    warnings = []
    for a in axes:
        try:
            model.machine.axes[a].check(dt, a)
            continue
        except ValueError as exc:  # unstable or badly damped (UnstableLoopError), or too fast for the servo period
            refused = exc
        start = None
        for widths in _STABILISING:
            for change, spread in _nuisance_changes(model, (a,), identified=False):
                (name, _), = change[a].items()
                value = getattr(model.machine.axes[a], name)
                for moved in (value * (1.0 + widths * spread), value * (1.0 - widths * spread)):
                    try:  # a move past a parameter's own range (a damping ratio to 0) is no plant: skipped
                        trial = _with_servos(model, {a: {name: moved}})
                        margin = min(m["gain_margin"] for m in trial.machine.axes[a].check(dt, a).values())
                    except (UnstableLoopError, ValueError):
                        continue
                    if start is None or margin > start[0]:
                        start = (margin, trial, name, value, moved, widths)
            if start is not None:
                break
        if start is None:
            raise UnstableLoopError(f"{refused} No plant within {_STABILISING[-1]:g} prior widths of the model's "
                                    "(one parameter moved) makes it pass", getattr(refused, "margins", None))
        margin, model, name, value, moved, widths = start
        warnings.append(f"axis {a}: the model's loop fails the loop check ({refused}) while the trace shows the machine "
                        f"stable: the diagnosis starts from {name} = {moved:.6g} (the model's {value:.6g}, {widths:g} "
                        f"prior widths), where the check passes (gain margin {margin:.3g})")
    return model, warnings


def _steps_from(nominal, machine, change):
    """How far `machine` is from `nominal` in the parameters of one nominal step, in units of that step (mean over its fields)."""
    steps = [(getattr(machine.axes[a], f) - getattr(nominal.axes[a], f)) / (v - getattr(machine.axes[a], f))
             for a, fields in change.items() for f, v in fields.items()]
    return float(np.mean(steps))


def _with_servos(model, change):
    """`model` with some servo fields changed, ``{axis: {field: value}}`` (same chain: one structure for a batch).

    A compliant screw's motor side keeps its share of a changed mass (and stays within 95 % of it).
    """
    machine = model.machine
    servos = dict(machine.axes)
    for axis, fields in change.items():
        s = servos[axis]
        if s.compliant:
            mass = fields.get("mass", s.mass)
            motor = fields.get("motor_mass", s.motor_mass * mass / s.mass)
            fields = {**fields, "motor_mass": min(motor, 0.95 * mass)}
        servos[axis] = replace(s, **fields)
    return Model(replace(machine, axes=servos), model.effects)


def _refitted(model, changes, coef, fraction=1.0):
    """`model` moved by `fraction` of `coef` times each change (a Gauss–Newton step), vff kept in [0, 1].

    Each field's move is first kept within ±50 % of its value, then scaled by `fraction`.
    """
    new = {}
    for change, c in zip(changes, coef):
        for axis, fields in change.items():
            for field, stepped in fields.items():
                old = getattr(model.machine.axes[axis], field)
                reach = 0.5 * (old if old > 0 else abs(stepped))
                value = old + fraction * float(np.clip(c * (stepped - old), -reach, reach))
                new.setdefault(axis, {})[field] = min(value, 1.0) if field == "vff" else value
    return _with_servos(model, new)


def _far_from_prior(nominal, refitted, axes):
    """A warning for each plant parameter the nominal refit moved more than :data:`_PRIOR_REACH` prior widths."""
    said = []
    for change, spread in _nuisance_changes(Model(nominal), axes, identified=False):
        (axis, fields), = change.items()
        (name, _), = fields.items()
        centre, value = getattr(nominal.axes[axis], name), getattr(refitted.axes[axis], name)
        if value is None:  # the axis's structure changed: a compliant screw taken as rigid for a vibration's mode
            continue
        widths = abs(value / centre - 1.0) / spread
        if widths > _PRIOR_REACH:
            said.append(f"{axis}.{name}: the nominal refit moved it {widths:.3g} prior widths ({value:.6g} against the "
                        f"model's {centre:.6g}): more than a data sheet is off; the trace pulls it towards something "
                        "the model lacks (see what the residual correlates with)")
    return said


@dataclass
class _Candidate:
    effect: Effect
    free: tuple
    grid: list
    x: np.ndarray = None
    residual: np.ndarray = None
    cost: float = np.inf
    fit: object = None
    uncertainty: dict = None
    delta_bic: float = -np.inf
    tau: float = 1.0
    settled: tuple = None  # (the base with it named, the warnings that brings) once profiled (:func:`_profiled`)
    moved: dict = None  # how far its fit moved as the nominal parameters were refitted around it, most over its settles
    lever: float = np.inf  # its ΔBIC fitted on the plant refitted around it, against that plant without it (:func:`_settle`)


def _candidates(problem, model, warnings):
    """Every catalogue effect on every axis of the trace it can act on, not yet in `model`.

    A vibration on an axis with a compliant screw is tried with the screw taken as rigid (:func:`_with_effect`):
    said once in `warnings`.
    """
    trace = problem.trace
    axes = trace.axes
    servo = [a for a in axes if a in model.machine.axes]
    have = _labels(model.effects)
    residual = problem.unwhiten(problem.base_residual)
    out = []

    def add(effect, free, grid):
        if effect.label not in have:
            out.append(_Candidate(effect, free, grid))

    def sizes(name, below=0):
        """`_GRID` values over the typical range of `name`'s size (each sign), plus `below` more grid steps under it."""
        p = effect_kind(name).parameters[0]
        lo, hi = p.typical
        values = np.geomspace(lo * (lo / hi) ** (below / (_GRID - 1)), hi, _GRID + below)
        return list(values) + (list(-values) if p.signed else [])

    dt = model.machine.servo_period
    # identified loops share one position gain: a gain mismatch of every axis is that gain moved, no effect (an
    # independent rigid gain mismatch of x, named, was named on y too, 0.63 µm left in 0.28 µm of noise)
    shared = problem.identified and sum(e.name == "gain_mismatch" for e in model.effects) >= len(servo) - 1
    for a in servo:
        s = model.machine.axes[a]
        # read where the axis's encoder is; on a rigid axis whose file says motor (the default), on a scale too:
        # the file may not say where its encoder is; the play centred at the start (closed by an approach: see
        # :func:`_approached`)
        for feedback in (s.position_feedback,) + (("scale",) if s.position_feedback == "motor" and not s.compliant else ()):
            add(Effect("backlash", a, lost_motion_um=1.0, feedback=feedback), ("lost_motion_um",),
                [{"lost_motion_um": v} for v in sizes("backlash")])
        # one step below the typical range too: a loop without velocity integrator stands still short of its
        # target by force/(kf·kv·kp), steep in the force, and an identified machine's forces are relative to
        # its assumed mass (the TU/e rig: 2.4 N, which a start at 5 N misses)
        add(Effect("coulomb_friction", a, force_N=1.0), ("force_N",),
            [{"force_N": v} for v in sizes("coulomb_friction", below=1)])
        if len(servo) > 1 and not shared:  # ln(kp_ratio) from 1 % to the typical range's edge, geometrically, each
            # sign: a mismatch of 2 % can leave a gap of many µm, which a start at ±5 % overshoots (no better than none)
            edge = -np.log(effect_kind("gain_mismatch").parameters[0].typical[0])
            add(Effect("gain_mismatch", a, kp_ratio=1.0), ("kp_ratio",),
                [{"kp_ratio": float(np.exp(sign * u))} for u in np.geomspace(0.01, edge, _GRID + 1) for sign in (-1, 1)])
        for kind in ("command", "feedback", "position"):
            top = 3e-3 if kind == "command" else min(3e-3, (MAX_DELAY_SAMPLES - 1) * dt)
            add(Effect("time_delay", a, delay_s=1e-4, kind=kind), ("delay_s",),
                [{"delay_s": v} for v in np.geomspace(min(1e-4, top / 4), top, _GRID)])
        nyquist = 0.5 / dt
        freqs = [f for f in np.geomspace(30.0, 150.0, _GRID) if f < 0.4 * nyquist]
        peak = _spectral_peak(trace.t, residual[:, axes.index(a)], 0.4 * min(nyquist, 0.5 / trace.dt))
        freqs += [peak] if peak is not None else []
        if freqs and s.compliant:
            rigid = (f"vibration.{a}: tried with the axis's compliant screw taken as rigid: the kernel holds one "
                     "structural mode per axis")
            warnings += [] if rigid in warnings else [rigid]
        if freqs:
            add(Effect("vibration", a, freq_hz=freqs[0]), ("freq_hz", "damping_ratio"),
                [{"freq_hz": f, "damping_ratio": z} for f in freqs for z in (0.02, 0.1)])
    for a in axes:
        i = axes.index(a)
        q = trace.reference[:, i]
        add(Effect("scale_error", a, ppm=1.0), ("ppm",), [{"ppm": v} for v in sizes("scale_error")])
        add(Effect("thermal_drift", a, rate_um_per_min=1.0), ("rate_um_per_min",),
            [{"rate_um_per_min": v} for v in sizes("thermal_drift")])
        # over where the axis is, not where it was told to be: the following error shifts the reference by up to a
        # few mm, the other way on the way back, and smears a screw's period over the reference
        period, _, amplitude, phase = _spatial_period(trace.actual[:, i], residual[:, i] - residual[:, i].mean())
        if period is not None and 0.1 <= period <= 1000.0:  # the residual's own sinusoid starts it too (a narrow valley)
            add(Effect("cyclic_error", a, amplitude_um=1.0, period_mm=period), ("amplitude_um", "phase_deg", "period_mm"),
                [{"amplitude_um": amplitude / _UM, "phase_deg": phase}]
                + [{"amplitude_um": v, "phase_deg": ph} for v in (1.0, 3.0) for ph in (0.0, 90.0, 180.0, 270.0)])
        # the guideway's bow over the axis's travel (machine coordinates); without one, over the trace's own extent
        # with its vertex free (:func:`_bow_grid`)
        start, end = model.machine.travel.get(a, (float(q.min()), float(q.max())))
        shortest = next(p.bounds[0] for p in effect_kind("straightness").parameters if p.name == "span_mm")
        for b in axes:
            if b != a and end - start >= shortest:  # a bow over less travel than that is no guideway's
                bow = Effect("straightness", a, peak_um=1.0, span_mm=end - start, start_mm=start, error_direction=b)
                if a in model.machine.travel:
                    add(bow, ("peak_um",), [{"peak_um": v} for v in sizes("straightness")])
                else:
                    add(bow, ("peak_um", "start_mm"), _bow_grid(start, end, sizes("straightness", below=_BOW_BELOW)))
    for a, b in combinations(axes, 2):
        add(Effect("squareness", a + b, angle_urad=1.0), ("angle_urad",), [{"angle_urad": v} for v in sizes("squareness")])
    return [c for c in out if c.grid]


def _bow_grid(start, end, peaks):
    """Starting values of a straightness over the trace's own extent [`start`, `end`] (no travel given): each of
    `peaks` with the bow's vertex at the extent's middle, at either end and one extent beyond each.

    Over a path that covers part of the travel a guideway's bow is a curvature and a slope, the slope set by where
    the vertex lies (the middle of the travel); with the travel unknown the vertex is fitted (``start_mm``, the
    span held at the extent: the peak is the sag over the extent, the curvature the guideway's). A squareness is the
    slope alone; it is told from a bow by the curvature (:func:`_twins`).
    """
    span = end - start
    return [{"peak_um": v, "start_mm": start + k * span} for k in (-1.0, -0.5, 0.0, 0.5, 1.0) for v in peaks]


def _spectral_peak(t, r, fmax):
    """Frequency [Hz] of the largest peak of `r`'s spectrum between 20 Hz and `fmax`, or ``None``."""
    if fmax <= 20.0 or len(r) < 64:
        return None
    dt = (t[-1] - t[0]) / (len(t) - 1)
    spec = np.abs(np.fft.rfft((r - r.mean()) * np.hanning(len(r))))
    f = np.fft.rfftfreq(len(r), dt)
    band = (f >= 20.0) & (f <= fmax)
    return float(f[band][np.argmax(spec[band])]) if np.any(band) else None


def _bounds(problem, cand):
    """Lower and upper bounds of `cand`'s free parameters: the catalogue's, the servo period's limits, a cyclic
    error's period by the stroke, a fitted bow's vertex by the path's extent."""
    effect, params = cand.effect, {p.name: p for p in cand.effect.parameters}
    limits = {}
    if effect.name == "vibration":  # a lightly damped mode: a fit that wants more damping is a filter in disguise
        limits["freq_hz"] = (1.0, 0.45 / problem.reference.dt)
        limits["damping_ratio"] = (params["damping_ratio"].bounds[0], _MODE_DAMPING_MAX)
    elif effect.name == "time_delay":
        top = 0.1 if effect.options["kind"] == "command" else (MAX_DELAY_SAMPLES - 1) * problem.reference.dt
        limits["delay_s"] = (0.0, top)
    elif effect.name == "straightness":  # a vertex fitted (:func:`_bow_grid`): within a few extents of the path
        q, span = problem.trace.reference[:, problem.trace.axes.index(effect.axis)], effect["span_mm"]
        middle = 0.5 * float(q.min() + q.max())
        limits["start_mm"] = (middle - (_BOW_REACH + 0.5) * span, middle + (_BOW_REACH - 0.5) * span)
    elif effect.name == "cyclic_error":  # at least one period within the stroke, else it is a bow or a slope
        travel = float(np.ptp(problem.trace.reference[:, problem.trace.axes.index(effect.axis)]))
        limits["period_mm"] = (params["period_mm"].bounds[0], max(travel, 2 * params["period_mm"].bounds[0]))
    lower = np.array([limits.get(n, params[n].bounds)[0] for n in cand.free])
    upper = np.array([limits.get(n, params[n].bounds)[1] for n in cand.free])
    return lower, upper


def _model_of(model, cand, x):
    """`model` with `cand`'s effect at free-parameter values `x`."""
    return _with_effect(model, cand.effect.with_values(**dict(zip(cand.free, x))))


def _with_effect(model, effect):
    """`model` with `effect`; a vibration on an axis with a compliant screw takes the axis rigid first.

    The kernel holds one structural mode per axis: a tool-side mode (30–150 Hz) below the screw's (hundreds of
    Hz) is the one the trace shows, the screw's quasi-static stretch what is given up.
    """
    servo = model.machine.axes.get(effect.axis)
    if effect.name == "vibration" and servo is not None and servo.compliant:
        rigid = replace(servo, motor_mass=None, screw_stiffness=None, screw_damping_ratio=None)
        model = Model(replace(model.machine, axes={**model.machine.axes, effect.axis: rigid}), model.effects)
    return model.with_effect(effect)


def _score(problem, cand, r, tau=None):
    """Fill `cand`'s cost, autocorrelation time and ΔBIC from its residual `r` (:meth:`_Problem.residual`).

    `tau`: the autocorrelation time to count samples with (default `r`'s own).
    """
    cand.cost = float(r @ r)
    cand.tau = autocorrelation_time(problem.samples(r)[problem.scored])
    rss0 = float(problem.base_residual @ problem.base_residual)
    cand.delta_bic = float(delta_bic(rss0, cand.cost, problem.n, len(cand.free), tau or cand.tau))


def _start(problem, cands, model, warnings):
    """Every candidate's grid in one batch: the best row becomes its starting point ``cand.x``, scored.

    Returns the candidates whose grid could be simulated; a candidate whose
    simulation fails is left out with a warning (the batch is then run one
    candidate at a time to find it).
    """
    rows, owner = [], []
    for i, cand in enumerate(cands):
        lower, upper = _bounds(problem, cand)
        for row in cand.grid:
            x = np.clip(np.array([row.get(n, cand.effect[n]) for n in cand.free], dtype=float), lower, upper)
            rows.append(x)
            owner.append(i)
    try:
        predictions = problem.predict([_model_of(model, cands[i], x) for i, x in zip(owner, rows)])
    except _FIT_FAILURES:
        predictions = [None] * len(rows)
        for i, cand in enumerate(cands):
            mine = [k for k, o in enumerate(owner) if o == i]
            try:
                for k, y in zip(mine, problem.predict([_model_of(model, cand, rows[k]) for k in mine])):
                    predictions[k] = y
            except _FIT_FAILURES as exc:
                warnings.append(f"{cand.effect.label}{_options(cand.effect)}: left out, its simulation failed ({exc})")
    best = {}
    for i, x, y in zip(owner, rows, predictions):
        if y is None:
            continue
        r = _finite(problem.residual(y))
        if i not in best or r @ r < best[i][1] @ best[i][1]:
            best[i] = (x, r)
    kept = []
    for i, cand in enumerate(cands):
        if i in best:
            cand.x, cand.residual = best[i]
            kept.append(cand)
    _rescore(problem, kept)
    return kept


def _rescore(problem, cands):
    """Score `cands` with one autocorrelation time, that of the best candidate's residual, so that they compare
    by their residual and their number of parameters alone."""
    if not cands:
        return
    best = min(cands, key=lambda c: float(c.residual @ c.residual))
    tau = autocorrelation_time(problem.samples(best.residual)[problem.scored])
    for cand in cands:
        _score(problem, cand, cand.residual, tau)


def _acceleration_twins(problem, cands, warnings):
    """`cands` less, on an identified machine, each scale error that a misfit of its axis's loop in proportion to
    that axis's acceleration explains as well (its ΔBIC no longer significant with that misfit taken out of both
    residuals); each significant one left out is said.

    On a circle at one feed an axis's acceleration is in proportion to its
    position about the centre (−ω²·(q − c)): a scale error, in proportion to
    the position about its mean, draws what loops that answer acceleration a
    little differently than identified do (the velocity loop's bandwidth,
    an acceleration feedforward) and fits it from the same trace. With a
    given model the mass's refit, within its prior, answers that misfit.
    """
    if not problem.identified:
        return cands
    n, d = problem.measured.shape
    acc = _on_trace(problem.trace, problem.reference.t, problem.reference.acceleration)
    kept = []
    for cand in cands:
        if cand.effect.name != "scale_error":
            kept.append(cand)
            continue
        i = problem.trace.axes.index(cand.effect.axis)
        column = np.zeros((n, d))
        column[:, i] = acc[:, i] - acc[problem.scored, i].mean()  # the instrument's zero is free: about the mean
        a = (column * problem.weight).ravel()
        if not a @ a > 0:
            kept.append(cand)
            continue

        def rss(r):
            return float(r @ r) - float(a @ r[: n * d]) ** 2 / float(a @ a)

        without = float(delta_bic(rss(problem.base_residual), rss(cand.residual), problem.n, len(cand.free), cand.tau))
        if without > SIGNIFICANT:
            kept.append(cand)
        elif cand.delta_bic > SIGNIFICANT:
            warnings.append(f"{cand.effect.label}: not named, on this path a misfit of the loop identified for "
                            f"{cand.effect.axis} in proportion to its acceleration explains it as well (ΔBIC "
                            f"{cand.delta_bic:.3g} -> {without:.3g} with that taken out): a path whose acceleration is "
                            "not in proportion to the position (a square; the circle at a second feed) tells them "
                            "apart, or give the nominal model (--model)")
    return kept


def _finite(r):
    """`r` with what a variant that went unstable left (non-finite or absurd entries) held at ±1e6 noise levels."""
    return np.clip(np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6), -1e6, 1e6)


def _refine(problem, cand, model):
    """Fit `cand`'s free parameters from its start through the simulator; fills the fit and its uncertainty."""
    lower, upper = _bounds(problem, cand)
    scale = _scales(problem, cand)
    cache = {}

    def residuals(xs):
        todo = [x for x in xs if x.tobytes() not in cache]
        if todo:
            for x, y in zip(todo, problem.predict([_model_of(model, cand, x) for x in todo])):
                cache[x.tobytes()] = _finite(problem.residual(y))
        return [cache[x.tobytes()] for x in xs]

    def fun(x):
        return residuals([x])[0]

    def jac(x):
        steps = []
        for j in range(x.size):
            h = _FD_STEP * max(abs(x[j]), scale[j])
            steps.append(h if x[j] + h <= upper[j] else -h)
        r0, *cols = residuals([x] + [x + h * np.eye(x.size)[j] for j, h in enumerate(steps)])
        return np.column_stack([(c - r0) / h for c, h in zip(cols, steps)])

    fit = least_squares(fun, cand.x, jac=jac, bounds=(lower, upper), x_scale=scale, max_nfev=25, xtol=1e-6, ftol=1e-8)
    x, j, r = _smoothed(fit.x, jac, residuals, scale, lower, upper)
    cand.residual = fun(x)
    _score(problem, cand, cand.residual)
    cand.fit = _model_of(model, cand, x).effects[-1]
    n, k = problem.n, len(cand.free)
    try:
        inverse = np.linalg.inv(j.T @ j)
        cov = _marginal(problem, j, cand.cost / max(n - k, 1) * cand.tau)
        spread = [_jackknife(problem, j, r, blocks) for blocks in _JACKKNIFE_BLOCKS]
        err = np.max([np.sqrt(np.clip(np.diag(cov), 0, None))] + spread, axis=0)
        err = np.sqrt(err**2 + np.sum(_held(problem, cand, model, inverse @ j.T) ** 2, axis=0))
    except np.linalg.LinAlgError:
        err = np.full(k, np.inf)
    cand.uncertainty = {name: float(e) for name, e in zip(cand.free, err)}


def _approached(problem, cand, model):
    """A backlash `cand`, refined with its play centred at the start: refined again with the play closed by an
    approach either way where that fits significantly better at its size (the approach counted as a parameter: else
    it bends to a misfit of the plant, as an independent two-mass backlash started centred did, its screw refitted
    five prior widths off), else as it is.

    A machine comes to a logged move's start by some move, which closes the play on its side; a play taken as
    centred leaves a step of half of it until the first move (an outside tester's backlash started so was named
    with a false scale error of 89 ppm beside it).
    """
    x = np.array([cand.fit[name] for name in cand.free])
    lower, upper = _bounds(problem, cand)
    wide = _WIDE_STEP * _scales(problem, cand)
    star = np.unique([np.clip(x + u * wide[i] * np.eye(x.size)[i], lower, upper)
                      for i in range(x.size) for u in range(-_WIDE_POINTS, _WIDE_POINTS + 1)], axis=0)
    # each way, centred too, at its best of the fit's wide star: one point of a profile as jagged as a backlash's
    # contacts make it chose the way by its notch (an independent 19.4 µm backlash approached in +: centred)
    ways = [_Candidate(cand.effect.with_values(approach=a), cand.free, cand.grid, x=p) for a in ("none", "+", "-")
            for p in star]
    predicted = problem.predict([_model_of(model, c, c.x) for c in ways])
    for way, y in zip(ways, predicted):
        _score(problem, way, _finite(problem.residual(y)), cand.tau)
    centred = min([cand] + ways[: len(star)], key=lambda c: c.cost)
    best = min(ways[len(star):], key=lambda c: c.cost)
    if not delta_bic(centred.cost, best.cost, problem.n, 1, cand.tau) > SIGNIFICANT:
        return cand
    try:
        _refine(problem, best, model)
    except _FIT_FAILURES:
        return cand
    return best if best.cost < cand.cost else cand


def _smoothed(x, jac, residuals, scale, lower, upper):
    """The fit `x` and the Jacobian and residual its uncertainty is judged by: `jac` and the residual at `x` where the
    residual is smooth in the parameters; regressed over a grid of wide steps where it is rough.

    A backlash's contacts, timed within servo periods, make the residual
    jagged in the lost motion at the scale of a finite-difference step: the
    fit stops in a notch (an independent lost motion of 19.8 µm left at its
    grid start, 20.0 µm, the profile's trend lowest near 19.5 µm) and the
    derivative there, and the spread linearised with it, are the notch's
    (±0.016 µm). A parameter is rough when its derivative at the
    finite-difference step differs from the central secant over
    ±:data:`_WIDE_STEP` of its scale by more than twice the secant (8–20
    times for a backlash read on a scale; at most 0.6 times for the
    catalogue's other effects, a cyclic error's period the largest). Its
    residual is then regressed on the rough parameters over a star of
    ±:data:`_WIDE_POINTS` wide steps around the fit, the others held, and
    the fit moved to the regression's least squares (recentred while that
    lands on the star's edge, up to :data:`_WIDE_POINTS` times); the
    regression's slopes and its residual there stand for the derivative and
    the residual: the profile with its notches averaged out.

    `jac` and `residuals` are :func:`_refine`'s (the latter takes a list of
    parameter vectors); `scale`, `lower` and `upper` its scales and bounds.
    Returns ``(x, j, r)``.
    """
    j, r = jac(x), residuals([x])[0]
    wide = _WIDE_STEP * scale
    ends = [np.clip(x + sign * w * np.eye(x.size)[i], lower, upper) for i, w in enumerate(wide) for sign in (-1, 1)]
    values = residuals(ends)
    secants = [(hi - lo) / (b[i] - a[i])
               for i, (a, b, lo, hi) in enumerate(zip(ends[::2], ends[1::2], values[::2], values[1::2]))]
    index = np.flatnonzero([np.linalg.norm(j[:, i] - c) > 2.0 * np.linalg.norm(c) for i, c in enumerate(secants)])
    if not index.size:
        return x, j, r
    span = _WIDE_POINTS * wide[index]
    x = x.copy()
    for _ in range(_WIDE_POINTS):
        star = np.unique([np.clip(x + u * wide[i] * np.eye(x.size)[i], lower, upper)
                          for i in index for u in range(-_WIDE_POINTS, _WIDE_POINTS + 1)], axis=0)
        design = np.column_stack([np.ones(len(star)), star[:, index] - x[index]])
        coef = np.linalg.lstsq(design, np.array(residuals(list(star))), rcond=None)[0]  # (1 + rough, M)
        intercept, slopes = coef[0], coef[1:].T
        step = -np.linalg.lstsq(slopes, intercept, rcond=None)[0]
        moved = np.clip(x[index] + np.clip(step, -span, span), lower[index], upper[index])
        r = intercept + slopes @ (moved - x[index])
        x[index] = moved
        if np.all(np.abs(step) < span):
            break
    if index.size < x.size:  # the smooth parameters' columns where the fit moved
        j = jac(x)
    j[:, index] = slopes
    return x, j, r


def _marginal(problem, j, variance):
    """The Gauss–Newton covariance of a fit's parameters, marginal over a time shift of each measured output.

    The residual's sensitivity to an output (an axis's position, a current)
    read τ late is its sensitivity to ``τ·ẏ`` (the base's rate of that output), through the
    nominal refit like any misfit; each τ carries the prior
    :data:`TIMING_SPREAD` of the servo period. `j` is the Jacobian of
    :meth:`_Problem.residual` in the fit's parameters, `variance` the
    residual's per entry (its autocorrelation counted). Returns (k, k).
    """
    y = problem.base_prediction
    r0 = problem.residual(y)
    velocity = np.gradient(y, problem.trace.t, axis=0)
    columns = []
    for i in range(y.shape[1]):
        shifted = y.copy()
        shifted[:, i] += velocity[:, i]  # a shift of 1 s, linearised: the residual is linear in the prediction
        columns.append(problem.residual(shifted) - r0)
    k, d = j.shape[1], len(columns)
    both = np.hstack([j] + [c[:, None] for c in columns])
    prior = np.concatenate([np.zeros(k), np.full(d, (TIMING_SPREAD * problem.base.machine.servo_period) ** -2)])
    return np.linalg.inv(both.T @ both / variance + np.diag(prior))[:k, :k]


def _held(problem, cand, model, pseudo):
    """How far each of `cand`'s parameters held at a default moves its fitted ones: one row per held parameter [units
    of the free ones], shape (h, k).

    An effect's parameters the fit does not vary but whose true value lies
    anywhere in a typical range (a vibration's tool-side mass ratio, a
    friction's Stribeck hump or viscous part) are nuisance parameters held
    at a guess: the fitted ones depend on the guess. Each held value φ₀ is
    moved by ``s``, the RMS distance of a value uniform over its typical
    range from φ₀; the secant's Gauss–Newton step, ``−pseudo·Δr``
    (`pseudo` = ``(JᵀJ)⁻¹Jᵀ`` of the fit, the nuisance refit profiled in
    `Δr`), is how far the fit would move if the truth lay there.
    """
    effect = cand.fit
    moved = []
    for p in effect.parameters:
        if p.name in cand.free or p.vary or p.typical is None:
            continue
        lo, hi = p.typical
        s = float(np.sqrt((hi - lo) ** 2 / 12.0 + ((hi + lo) / 2.0 - p.value) ** 2))
        value = p.value + s if p.value + s <= p.bounds[1] else p.value - s
        if s > 0 and p.bounds[0] <= value <= p.bounds[1]:
            moved.append(_with_effect(model, effect.with_values(**{p.name: value})))
    if not moved:
        return np.zeros((0, len(cand.free)))
    return np.array([-pseudo @ (_finite(problem.residual(y)) - cand.residual) for y in problem.predict(moved)])


def _jackknife(problem, j, r, blocks):
    """Block-jackknife standard deviation of a fit's parameters, linearised around the optimum.

    The scored samples are cut into `blocks` consecutive segments; leaving
    segment b out moves the parameters by one Gauss–Newton step,
    ``(JᵀJ − J_bᵀJ_b)⁻¹·J_bᵀ·r_b`` (at the optimum ``Jᵀr = 0``), and the
    spread of these moves, ``√((B−1)/B·Σ(δ_b − δ̄)²)``, is the jackknife's
    standard deviation: a model error that pulls the parameter differently
    along the trace shows in it, white noise alone gives the usual one.

    Parameters
    ----------
    problem : _Problem
    j : ndarray, shape (M, k)
        Jacobian of the residual `r` (:meth:`_Problem.residual`) in the free parameters.
    r : ndarray, shape (M,)
    blocks : int
        Segments (0 when the trace has fewer than 4 scored samples per segment).

    Returns
    -------
    ndarray, shape (k,)
    """
    d = problem.measured.shape[1]
    rows = np.flatnonzero(problem.scored)
    if rows.size < 4 * blocks:
        return np.zeros(j.shape[1])
    edges = np.linspace(0, rows.size, blocks + 1).astype(int)
    normal = j.T @ j
    moves = []
    for b in range(blocks):
        index = (rows[edges[b]:edges[b + 1], None] * d + np.arange(d)).ravel()
        jb = j[index]
        moves.append(np.linalg.solve(normal - jb.T @ jb, jb.T @ r[index]))
    moves = np.array(moves)
    return np.sqrt((blocks - 1) / blocks * np.sum((moves - moves.mean(axis=0)) ** 2, axis=0))


def _scales(problem, cand):
    """The size of a step in each of `cand`'s free parameters that matters (the fit's x_scale; its finite differences
    step a thousandth of it, or of the value): the top of a typical range, else of the bounds; a cyclic error's
    period by what drifts its phase a radian from one end of the stroke to the other (``period²/(2π·stroke)``); a
    fitted bow's vertex by its span."""
    out = []
    for name in cand.free:
        p = next(p for p in cand.effect.parameters if p.name == name)
        lo, hi = p.bounds
        scale = p.typical[1] if p.typical is not None else (hi - lo) if np.isfinite(hi - lo) and hi - lo < 1e3 else 1.0
        if cand.effect.name == "cyclic_error" and name == "period_mm":
            stroke = float(np.ptp(problem.trace.reference[:, problem.trace.axes.index(cand.effect.axis)]))
            scale = min(scale, p.value**2 / (2 * np.pi * max(stroke, p.value)))
        elif cand.effect.name == "straightness" and name == "start_mm":
            scale = cand.effect["span_mm"]
        out.append(scale)
    return np.array(out)


def turning(position, velocity):
    """How much of a path turns counterclockwise and how much clockwise in the plane of its first two axes.

    The sense of each moving sample is the sign of ``(p − c) × v``, ``c`` the
    middle of the path's bounding box: a circle, a square or a trefoil run
    one way turns one way all along; run out and back (CCW then CW, as a
    ballbar test does), half each.

    Parameters
    ----------
    position, velocity : ndarray, shape (N, d)
        Commanded positions [mm] and velocities [mm/s].

    Returns
    -------
    (float, float)
        Shares of the moving samples turning counterclockwise and clockwise
        [-]; (0, 0) for one axis or a path that does not move.
    """
    if position.shape[1] < 2:
        return 0.0, 0.0
    p = position[:, :2] - (position[:, :2].max(axis=0) + position[:, :2].min(axis=0)) / 2
    cross = p[:, 0] * velocity[:, 1] - p[:, 1] * velocity[:, 0]
    speed = np.linalg.norm(velocity[:, :2], axis=1)
    moving = cross != 0
    moving &= np.abs(cross) > 1e-9 * float(np.max(np.abs(cross), initial=0.0))
    moving &= speed > 1e-3 * float(speed.max(initial=0.0))
    if not moving.any():
        return 0.0, 0.0
    return float(np.mean(cross[moving] > 0)), float(np.mean(cross[moving] < 0))


def _look_alikes(problem, best, cands, both_ways):
    """The candidates the trace cannot tell from `best`, and why: ``[(candidate, reason)]``, best ranked first.

    Each either a rival within :data:`SIGNIFICANT` of the best's ΔBIC, or one of a
    pair whose difference lies in what a trace may not hold
    (:func:`_twins`) that closes at least :data:`_TWIN_SHARE` of what the
    best closes and leaves at most :data:`_TWIN_RMS` times its residual RMS
    (in noise levels: what the trace does hold tells apart a pair that far
    apart; an independent delay of y's position reading of 0.17 ms on a
    one-way circle, fitted to the noise, was taken for a squareness's twin
    that left 8.2 noise levels, 82 % of its gap closed, and the squareness
    was named with 1.51 µm left in 0.19 µm of noise; a Y gain 1 % low on the
    ISO 230-4 circle run one way, fitted to the noise, leaves the
    squareness 3.4 noise levels, and stays its twin):

    - a squareness and a position-gain mismatch (or a delay, of the command
      or of the loop's reading) of one axis both draw an oval at
      45° on a circle (ballbar reasoning, ISO 230-4,
      Renishaw QC20): the squareness's keeps its orientation in both
      directions and its size at any feed, the servo effect's flips between
      CW and CCW and grows with the feed. A trace run both ways (:func:`turning`)
      lets the fit tell them apart, each candidate being simulated both ways;
      one run one way cannot;
    - a squareness and a straightness in its plane: over a path small against
      the travel a straightness is mostly a slope, the shear of a squareness;
      only its curvature, the sag over the path, tells it.
    """
    rss0 = float(problem.base_residual @ problem.base_residual)
    closed = rss0 - best.cost
    found = []
    for c in cands[1:]:
        why = _twins(best.fit, c.fit, both_ways) if closed > 0 else None
        if c.delta_bic > best.delta_bic - SIGNIFICANT:
            found.append((c, f"they explain the data almost equally (ΔBIC {best.delta_bic:.0f} vs {c.delta_bic:.0f})"))
        elif why is not None and rss0 - c.cost >= _TWIN_SHARE * closed and c.cost <= _TWIN_RMS**2 * best.cost:
            found.append((c, f"both explain the trace (one {100 * (rss0 - c.cost) / closed:.0f} % of what the other does): {why}"))
    return found


def _choose(problem, cands, both_ways):
    """The candidate to name among `cands` (sorted best first), and the ambiguities to report (a list of sentences).

    The best, unless it is a delay of an axis's position-loop reading that
    the trace does not tell from a gain mismatch of that axis
    (:func:`_first_order_twin`: the gain is named; a best gain is named with
    such a delay said beside it), or the trace cannot tell it from its twins
    (:func:`_look_alikes`) and a twin is more plausible (:func:`_plausible`:
    its size lies within the catalogue's typical range and the best's does
    not; or, their sizes alike typical or not, it leaves as given a
    controller the model gives exactly and the best does not): what the trace cannot decide, the
    typical sizes of machines and the data sheet may; the best ranked such
    twin is named. Either way the pair is reported, with the test that would
    separate them; so is every other twin of the best (a gain of one axis,
    the opposite gain of the other and a squareness may all fit a one-way
    circle alike).
    """
    best = cands[0]
    pair = _first_order_twin(problem, best, cands)
    if pair is not None and pair[1] is best:
        return _first_order_said(problem, *pair, both_ways)
    twins = _look_alikes(problem, best, cands, both_ways)
    if not twins:
        return _first_order_said(problem, *pair, both_ways) if pair is not None else (best, [])
    rank = lambda c: _plausible(problem, c.fit)  # noqa: E731
    named, reason = max([(best, None)] + twins, key=lambda option: rank(option[0]))  # the first of the most plausible
    swap = named is not best
    twin, reason = (named, reason) if swap else twins[0]
    why_named = ""
    if swap:
        why_named = ("the first is named, its size typical and the second's not; " if rank(named)[0] > rank(best)[0] else
                     f"the first is named: the model gives {_departs_from(problem, best.fit)} exactly, the second "
                     "departs from it and the trace cannot tell; ")
    pairs = [(named, best if swap else twin, reason, why_named)] + [(best, c, why, "") for c, why in twins if c is not twin]
    return named, [
        f"{a.fit.label}{_options(a.fit)} ({_size(a.fit)}) and {b.fit.label}{_options(b.fit)} ({_size(b.fit)}): {why}; "
        + said + f"to separate them: {_separating_test(a.fit, b.fit, both_ways)}" for a, b, why, said in pairs]


def _plausible(problem, effect):
    """How plausible `effect` is before the trace speaks, a sort key (:func:`_choose`): its size typical, then no
    departure from a controller setting the model gives exactly (:func:`_departs_from`).

    A straightness over the trace's own extent (no travel given: :func:`_bow_grid`) is the sag over the path of a bow
    over a travel unknown: the catalogue's typical peak, over a travel, does not judge it (an independent two-mass
    bow of 5.1 µm over 400 mm, 0.28 µm over a 93 mm square, was named after a squareness for that).
    """
    bow = effect.name == "straightness" and effect.axis not in problem.nominal.travel
    return bow or _typical(effect), _departs_from(problem, effect) is None


def _departs_from(problem, effect):
    """The controller setting the model gives exactly that `effect` says is otherwise (its name), or ``None``.

    A given model's controller is trusted (its settings are software constants; the plant carries the prior): a gain
    mismatch departs from the axis's position gain unless the machine lists ``kp`` as ``uncertain``, a delay from
    its loop's timing. Identified loops give nothing exactly.
    """
    if problem.identified:
        return None
    if effect.name == "gain_mismatch" and "kp" not in problem.nominal.uncertain.get(effect.axis, ()):
        return f"{effect.axis}'s position gain"
    if effect.name == "time_delay":
        return f"{effect.axis}'s loop timing"
    return None


def _first_order_twin(problem, best, cands):
    """``(gain, delay)``: `best` and the candidate the trace does not tell from it, when one is a gain mismatch and
    the other a delay of the same axis's position-loop reading; ``None`` when `best` is neither, or the trace tells
    them apart.

    At constant speed the loop drives what it reads to a lag v/kp, the axis v·τ further on: the lag of a gain
    kp/(1 − kp·τ). The delay's own mark, the phase ω·τ it takes beyond that gain's, is of second order, and a model
    a little wrong elsewhere fits it as readily. Either is told from the other as an effect is named: when its fit is
    significant beyond the other's (ΔBIC more than :data:`SIGNIFICANT` higher) and closes at least :data:`GAP_SHARE`
    of what the other's leaves above the noise floor.
    """
    other = _partner(best, cands)
    if other is None:
        return None
    gain, delay = (best, other) if best.fit.name == "gain_mismatch" else (other, best)
    above = other.cost - problem.n  # what the other's fit leaves above the noise floor (whitened: n entries of 1)
    told = best.delta_bic > other.delta_bic + SIGNIFICANT and above > 0 and other.cost - best.cost >= GAP_SHARE * above
    return None if told else (gain, delay)


def _partner(cand, cands):
    """The candidate among `cands` that `cand` is to first order (:func:`_first_order_twin`): a gain mismatch's delay
    of the same axis's position-loop reading, or that delay's gain mismatch; ``None`` for any other or none there."""
    if cand.fit.name == "gain_mismatch":
        twin = lambda c: c.fit.name == "time_delay" and c.fit.options["kind"] == "position"  # noqa: E731
    elif cand.fit.name == "time_delay" and cand.fit.options["kind"] == "position":
        twin = lambda c: c.fit.name == "gain_mismatch"  # noqa: E731
    else:
        return None
    return next((c for c in cands if c.fit.axis == cand.fit.axis and twin(c)), None)


def _first_order_said(problem, gain, delay, both_ways):
    """The gain named over the delay it is to first order (:func:`_first_order_twin`), and the pair said (one sentence
    in a list, as :func:`_choose` gives them)."""
    above = gain.cost - problem.n  # what the gain's fit leaves above the noise floor (whitened: n entries of 1)
    closing = (f"the delay closing {max(gain.cost - delay.cost, 0.0) / above:.0%} of what the gain leaves above the noise "
               "floor" if above > 0 else "the gain leaving nothing above the noise floor")
    return gain, [(f"{gain.fit.label} ({_size(gain.fit)}) and {delay.fit.label}{_options(delay.fit)} ({_size(delay.fit)}): "
                  f"the trace does not tell the delay from the gain it is to first order (ΔBIC {delay.delta_bic:.0f} "
                  f"vs {gain.delta_bic:.0f}, {closing}; told apart beyond {SIGNIFICANT:g} and from {GAP_SHARE:.0%}): "
                  f"the gain is named; to separate them: {_separating_test(gain.fit, delay.fit, both_ways)}")]


def _delay_as_ratio(delay, kp, other):
    """What to say of a `delay` named on identified loops of two axes sharing one position gain `kp` [1/s] (a list of
    one sentence, or empty): to first order it is a gain of its axis, kp/(1 + kp·τ) for a command late by τ, kp/(1 −
    kp·τ) for a reading late by τ, and only the ratio of the two axes' gains is known; the `other` axis's gain by the
    inverse ratio fits alike (an outside tester's Y gain 0.8 times X's was named, without the model, as a delay of 1.81
    ms of X's reading)."""
    kp_tau = kp * delay["delay_s"]
    command = delay.options["kind"] == "command"
    if not command and kp_tau >= 1.0:
        return []
    ratio = 1.0 / (1.0 + kp_tau) if command else 1.0 / (1.0 - kp_tau)
    what = "command" if command else "reading"
    return [f"{delay.label}: with one position gain identified for both axes, a delay of {delay.axis}'s {what} of "
            f"{1e3 * delay['delay_s']:.3g} ms is to first order {delay.axis}'s gain times {ratio:.4g}, and only the ratio "
            f"of the axes' gains is known: to first order the same machine as a kp_ratio of {1.0 / ratio:.4g} on {other} "
            f"(gain_mismatch.{other}); to separate them: the data sheet's gains (diagnose --model), or a step of each "
            "axis alone"]


def _typical(effect):
    """The effect's size (its first parameter; the magnitude of a signed one) lies within its typical range (if any)."""
    size = effect.parameters[0]
    if size.typical is None:
        return True
    lo, hi = size.typical
    return lo <= (abs(size.value) if size.signed else size.value) <= hi


def _size(effect):
    size = effect.parameters[0]
    return f"{size.name} = {size.value:.4g}"


def _twins(a, b, both_ways):
    """Why effects `a` and `b` look alike on a trace (:func:`_look_alikes`), or ``None``."""
    if {_oval_kind(a), _oval_kind(b)} == {"geometry", "servo"} and not both_ways:
        return "both draw an oval at 45° on a circle, and the trace runs its path one way only"
    if {a.name, b.name} == {"squareness", "straightness"}:
        square, bow = (a, b) if a.name == "squareness" else (b, a)
        if set(bow.axis + bow.options["error_direction"]) == set(square.axis):
            return "over a path small against the travel a straightness is mostly a slope, a squareness's shear"
    return None


def _oval_kind(effect):
    """``"geometry"`` for a squareness, ``"servo"`` for a gain mismatch or a delay of any kind (a command delay lags
    like a gain, a delay of the loop's reading is one to first order, ``kp/(1 − kp·τ)``: all draw a 45° oval on a
    circle), else ``None``."""
    if effect.name == "squareness":
        return "geometry"
    if effect.name in ("gain_mismatch", "time_delay"):
        return "servo"
    return None


#: What tells a squareness from a straightness's slope over the path (:func:`_separating_test`).
_SLOPE_TEST = ("the same path placed elsewhere in the travel, or a straightness measurement over the whole travel "
               "(ISO 230-1): a straightness's slope changes with where the path lies, a squareness's does not")


def _separating_test(a, b, both_ways=False):
    """The extra test that tells effect `a` from effect `b` (`both_ways`: the trace already runs its path both ways)."""
    kinds = {e.options["kind"] for e in (a, b) if e.name == "time_delay"}
    if a.name == b.name == "time_delay" and "command" not in kinds:
        return ("a velocity step, or the drive's own velocity record: a delay of both loops' feedback slows the velocity "
                "loop too (it overshoots at its own bandwidth), a delay of the position loop's reading leaves it as it was")
    if a.name == b.name == "time_delay":
        return "a step or a faster reversal: a feedback delay changes the loop's damping (overshoot), a command delay only shifts the response"
    if {a.name, b.name} == {"gain_mismatch", "time_delay"} and kinds != {"command"}:
        return ("a position step: to first order a delay τ of the loop's reading is a gain kp/(1 − kp·τ), but a higher "
                "gain speeds the response from the first servo period, while the delayed loop starts at the nominal "
                "rate and overshoots more (the phase it loses, ω·τ, grows with the frequency)")
    if {a.name, b.name} == {"gain_mismatch", "time_delay"}:
        return ("a position step, or the path at a higher acceleration: both lengthen the lag in proportion to the "
                "speed, but a gain change alters the closed loop's dynamics (how it settles after a start, a stop or a "
                "corner, and the lag while accelerating), a delay only shifts the response in time")
    if a.name == b.name == "backlash":
        return "a reversal test read on the motor encoder and on a linear scale: with motor feedback the table lags, with scale feedback the loop chases the lost motion"
    if {a.name, b.name} == {"squareness", "straightness"}:
        return _SLOPE_TEST
    if {a.name, b.name} == {"scale_error", "thermal_drift"}:
        return "the same move at another feed, or with a dwell: a drift grows with time, a scale error with position"
    stages = {a.stage, b.stage}
    if "geometry" in stages and len(stages) > 1:
        if both_ways:
            return "run the path again at a second feed: geometric errors keep their size, servo effects grow with the feed"
        return ("run the circle in the other direction and at a second feed: geometric errors keep their shape, "
                "servo effects flip with the direction and grow with the feed")
    if stages == {"geometry"}:
        return "a circle of another radius, or straight-line tests along each axis (ISO 230-2)"
    return "repeat the test at a second feed and in the other direction: the two effects scale differently with speed and acceleration"


# -- the workflow ------------------------------------------------------------------------------


@one_blas_thread
def diagnose(trace, model=None, max_effects=MAX_EFFECTS, progress=None):
    """Name the catalogue effects a nominal model lacks to explain a measured trace (module docstring).

    Parameters
    ----------
    trace : contoursim.traces.Trace
        The measured trace (1–3 axes).
    model : Model or Machine, optional
        The nominal model; its servo axes must include the trace's axes.
        ``None``: identified from the trace (:func:`contoursim.identify.identify_machine`); where
        the effects named include one in the loops and leave more than twice the noise, the loops
        are identified again with them held in place and the diagnosis starts over (said in a
        warning when that closes the gap); where nothing was named against such a misfit, so is
        the best candidate that fell short, unless a geometric one, and where none fell short (or
        only geometric effects were named against it), the friction, backlash or feedback delay of
        an axis that the loops, identified with it held, follow closest; where nothing is named
        above the noise floor, so is the structural mode.
    max_effects : int
        Most effects to name.
    progress : callable, optional
        Called with one line of text per candidate fitted (the CLI prints it to stderr).

    Returns
    -------
    Diagnosis

    Raises
    ------
    TypeError
        `trace` is not a Trace, `model` not a Model or Machine, `max_effects`
        not a whole number.
    ValueError
        The trace has fewer than 3 samples (the noise floor is estimated
        from second differences), or fewer than 16 without a model (none
        to identify the loops from), the model lacks one of its axes, or
        `max_effects` is negative.
    """
    if not isinstance(trace, Trace):
        raise TypeError(f"trace must be a Trace (contoursim.read_trace reads one from its CSV file), got "
                        f"{type(trace).__name__}")
    if isinstance(max_effects, (bool, np.bool_)) or not isinstance(max_effects, (int, np.integer)):
        raise TypeError(f"max_effects must be a whole number, got {max_effects!r}")
    if max_effects < 0:
        raise ValueError(f"max_effects must be zero or more, got {max_effects}")
    if len(trace.t) < 3:
        raise ValueError(f"a diagnosis needs at least 3 samples (its noise floor is estimated from second differences); "
                         f"the trace has {len(trace.t)}")
    say = _validate.callback("progress", progress) or (lambda text: None)
    if model is not None:
        return _diagnose(trace, as_model(model), False, max_effects, say)[0]
    say("no nominal model given: identifying the servo loops from the trace")
    result, near = _diagnose(trace, Model(identify_machine(trace, progress=say)), True, max_effects, say)
    result, near = _geometry_held(trace, result, near, max_effects, say)
    if near or not _unexplained(result):
        result = _reidentified(trace, result, near, False, max_effects, say)
    if _unexplained(result, in_loops=True):
        # nothing in the loops named against a clear misfit, and no candidate that fell short or none that was named on
        # the loops identified with it held: the loops may have bent to a friction, a backlash or a delay
        searched, loops = _held_search(trace, result, _drive_held, say)
        result = _reidentified(trace, result, searched, True, max_effects, say, loops=loops)
    if _unexplained(result, NOISE_FLOOR):
        # or to a structural mode, whose quasi-static deflection they take up as lag: what it leaves, its ringing where
        # the path accelerates, is small over the whole trace
        searched, loops = _held_search(trace, result, _modes_held, say)
        result = _reidentified(trace, result, searched, True, max_effects, say, gap=NOISE_FLOOR, loops=loops)
    return result


def _unexplained(result, gap=_REIDENTIFY_GAP, in_loops=False):
    """Nothing named in `result`, a diagnosis on identified loops (with `in_loops`: nothing in the loops, geometric
    effects aside), against a misfit of more than `gap` noise levels (RMS)."""
    named = [e for e in result.effects if not (in_loops and e.stage == "geometry")]
    return not named and result.steps[-1].rms_um > gap * np.linalg.norm(result.noise_um)


def _reidentified(trace, result, near, searched, max_effects, say, gap=_REIDENTIFY_GAP, loops=None):
    """`result`, a diagnosis on identified loops, or the diagnosis on loops identified again with its effects held in
    place (with the first of `near`, candidates that fell short, where it named none), at most :data:`_REIDENTIFY`
    times, where it leaves more than `gap` noise levels and that closes the gap (:func:`diagnose`); `searched`: `near`
    is what :func:`_held_search` found, and `loops` the machine it identified with it held, which the first
    diagnosis takes where the effect is named on it (:func:`_identified_again`)."""
    for _ in range(_REIDENTIFY):
        # identified alone, the loops bend to an effect in them (one shared position gain to one axis's gain mismatch
        # or delay) and may take up most of it: where the effects named include one in the loops and leave a clear
        # misfit, they are held in place while the loops are identified again, and the diagnosis starts over from those
        # loops; where nothing was named against a clear misfit, so is the best candidate that fell short (its fit on
        # the bent loops), unless geometric. Kept when it names as many effects and, with as many named, closes most of
        # what the first left above the noise floor (less is the loops' own misfit moved about, for the next effect to
        # be bent to); a candidate that fell short, when it is then named and what is left lies within the noise
        # levels that called for it (less is its fit bent to that misfit); an effect searched for (_held_search),
        # when it is then named (its size was not fitted on the bent loops), also where only geometric effects were
        # named (a bow fitted to part of what an independent rigid feedback delay of 0.23 ms left on loops bent to it,
        # 8.93 -> 6.07 µm RMS in 0.30 µm of noise; on the loops identified with the delay held at 0.31 ms it is named
        # at 0.216 ms, 1.44 µm left, and on those identified once more around that at 0.227 ms, 0.33 µm left)
        left, floor = result.steps[-1].rms_um, float(np.linalg.norm(result.noise_um))
        in_loops = any(e.stage != "geometry" for e in result.effects)
        held = result.effects if in_loops or (result.effects and not searched) else tuple(near[:1])
        if all(e.stage == "geometry" for e in held) or not left > gap * floor:
            break
        labels = ", ".join(e.label for e in held)
        again, near_again = _identified_again(trace, held, max_effects, say, loops)
        loops = None
        if again is None:
            result = replace(result, warnings=result.warnings + (near_again,))
            break
        near = near_again
        k = len(held)  # steps: the nominal model, its refit, then one per effect
        unsure = not in_loops and ((held[0].name, held[0].axis) not in {(e.name, e.axis) for e in again.effects}
                                   or not (searched or again.steps[-1].rms_um <= _REIDENTIFY_GAP * floor))
        if unsure or len(again.effects) < k or not left**2 - again.steps[k + 1].rms_um**2 >= _REIDENTIFY_SHARE * (
                left**2 - floor**2):
            break  # loops that explain the trace only without the effects they were identified with: not the premise
        named = " and ".join(e.label for e in result.effects) + (" were" if len(result.effects) > 1 else " was")
        bent = (f"the loops identified before had bent to them: the diagnosis left {left:.4g} µm RMS" if in_loops
                else f"the loops identified before had taken it up: {named if result.effects else 'nothing was'} "
                     f"named, {left:.4g} µm RMS left")
        result = replace(again, warnings=again.warnings + (
            f"the servo loops were identified again with {labels} held in place ({bent}, now "
            f"{again.steps[-1].rms_um:.4g} µm)",))
    return result


def _held_search(trace, result, held_on, say):
    """``([the effect], the loops)``: the effect held in place with which the loops identified from `trace` follow it
    closest, of those ``held_on(axis)`` lists for each moving axis, one list a kind at sizes over its typical range,
    and those loops (``([], None)`` where none was identified).

    For a diagnosis on identified loops that named nothing against a misfit and had no candidate that fell short to
    identify them again with, or none that was named on the loops identified with it held: the loops bent to what
    is missing (:func:`_drive_held`, :func:`_modes_held`), so that no candidate fitted on them explains it, whatever
    its start; identified with it held, they are the trace's without it. Each list is tried at its middle size first,
    and the other sizes only of those that leave no more than :data:`_HELD_SCREEN` times the least RMS there: held at
    its middle size an effect that stands out leaves far less than any other (an independent rigid backlash of Y of
    19.8 µm read by a scale: 0.829 µm RMS held at 6.3 µm, every other kind and axis 1.378 µm or more; 0.313 µm at
    20 µm), while one held far from its own size may leave more than another (an independent two-mass backlash of Y
    read by the motor's encoder: 4.70 µm held at 6.3 µm, a backlash of X read by a scale 3.84 µm; 1.16 µm at 20 µm).
    Each is identified by one fit from `result`'s loops (those that named nothing) on each drive structure
    (:func:`identify_machine`'s `start`), not by its staged search from the trace's regression (1.3–2.5 times as
    long where the search runs, the same effects named on 88 independent cases); a PI loop and a damping are free in
    every fit (loops without an integrator, held around a friction of 58.5 N, left 12.50 µm RMS of an independent
    two-mass trace, the staged search's 3.90 µm), and every structure is tried (a mode held leaves no need of the
    computation delay the loops had bent to: 0.883 µm on theirs, 0.432 µm without it). The identifications of a
    batch (the middle sizes, then the other sizes screened in) run side by side, one a core (:func:`fork_map`).
    The diagnosis then runs on the loops found where it names the effect on them (:func:`_identified_again`), not on
    loops identified once more by the staged search around the same effect (an independent rigid backlash on a
    square run six times: 41.4 -> 24.7 s, and the false scale error named beside it there is not; over 132 bench
    cases two backlashes more named right, none fewer).
    """
    def cost(effect):
        """The sum of squares the loops identified with `effect` held leave, and those loops."""
        try:
            model = Model(identify_machine(trace, effects=(effect,), start=result.model.machine), (effect,))
            reference = measured_reference(trace, model.machine.servo_period)
            y = simulate_batch([model], reference, settle=0.0, check=False)["tool_position"][0]
        except _FIT_FAILURES:
            return np.inf, None
        r = trace.actual - _on_trace(trace, reference.t, y)
        return float(np.sum((r - r.mean(axis=0)) ** 2)), model.machine

    def costs(effects):
        say(f"identifying the servo loops {len(effects)} times, each with one held in place: "
            + "; ".join(f"{e.label}{_options(e)}, {_size(e)}" for e in effects))
        return fork_map(cost, effects, done=lambda k: say(f"identifying the servo loops with effects held in place: "
                                                          f"{k} of {len(effects)} done"))

    kinds = [sizes for axis, moving in zip(trace.axes, np.ptp(trace.reference, axis=0) > 0) if moving
             for sizes in held_on(axis)]
    middle = [sizes[(len(sizes) - 1) // 2] for sizes in kinds]
    tried = [(c, effect, loops) for (c, loops), effect in zip(costs(middle), middle)]
    least = min((c for c, _, _ in tried), default=np.inf)
    if not np.isfinite(least):
        return [], None
    others = [effect for (c, m, _), sizes in zip(tried, kinds)
              if c <= _HELD_SCREEN**2 * least  # costs are sums of squares
              for effect in sizes if effect is not m]
    if others:
        tried += [(c, effect, loops) for (c, loops), effect in zip(costs(others), others)]
    _, effect, loops = min(tried, key=lambda found: found[0])
    return [effect], loops


def _drive_held(axis):
    """A friction, a backlash read by the motor's encoder, one read by a scale and a delay of the feedback of `axis`,
    each a list at sizes over its typical range, to hold while its loops are identified (:func:`_held_search`).

    Loops identified with a friction in the trace bend to it (an independent two-mass friction took the shared kp
    from 44 to 186 1/s behind a feedforward of 1, where only the transients show kp), and on them no friction fits,
    whatever its size (every candidate's start lowered nothing). Identified with the friction held, the loops are the
    trace's without it (there 23 N on the assumed mass left 1.6 µm against 8.2). Likewise a backlash, its axis then
    identified as two masses at a finer servo period (:func:`~contoursim.identify.identify_machine`): an independent
    rigid 15.7 µm play read by the motor's encoder, on a square, left 6.30 µm RMS in 0.30 µm of noise, nothing named
    (nor on the loops identified around a delay that fell short); on the loops identified with the backlash held it
    is named at 15.78 µm, 0.371 µm left.
    """
    frictions = [Effect("coulomb_friction", axis, force_N=float(force))
                 for force in np.geomspace(*effect_kind("coulomb_friction").parameters[0].typical, _HELD_SIZES)]
    plays = [[Effect("backlash", axis, lost_motion_um=float(size), feedback=feedback)
              for size in np.geomspace(*effect_kind("backlash").parameters[0].typical, _HELD_PLAYS)]
             for feedback in ("motor", "scale")]
    delays = [Effect("time_delay", axis, delay_s=float(delay), kind="feedback")
              for delay in np.geomspace(*effect_kind("time_delay").parameters[0].typical, _HELD_SIZES)]
    return [frictions, *plays, delays]


def _modes_held(axis):
    """A structural mode of `axis` at frequencies over its typical range, each a list of its own, to hold while its
    loops are identified (:func:`_held_search`): a mode far above the path's frequencies is a lag, one near them rings,
    and how close the loops come to the trace is no smooth function of the frequency (an independent two-mass
    backlash of X on a circle, a mode of Y held: 1.48, 1.62 and 1.37 µm RMS left at 44.9, 100 and 150 Hz), so no one
    frequency screens the others.

    On a path's steady curves a tool-side mode far above the path's frequencies deflects the tool by the acceleration
    over the mode's ω², a lag that the identified loops take up; what it leaves, its ringing where the acceleration
    steps, is a small part of the whole trace's residual, and no vibration fits on the bent loops: an independent
    rigid 88 Hz mode of y on a circle left 0.559 µm RMS in 0.405 µm of noise, nothing named; the loops identified with
    a mode of y held at 100 Hz left 0.432 µm, and on them it is named at 94.0 Hz, 0.424 µm left.
    """
    return [[Effect("vibration", axis, freq_hz=float(f))]
            for f in np.geomspace(*effect_kind("vibration").parameters[0].typical, _HELD_MODES)]


def _geometry_held(trace, result, near, max_effects, say):
    """`result` of a diagnosis on identified loops, or the diagnosis on loops identified with its geometric effects
    held in place where that names fewer effects and leaves no more (where only geometric effects are named: the same
    ones, leaving no more): ``(Diagnosis, near)`` as :func:`_diagnose`'s.

    Loops identified from a trace with a geometric error in it bend to it (a screw's cyclic error of 3.6 µm on a
    circle took x's loop with it), and a loop effect named beside the geometric one takes up what they bent (a gain
    mismatch of 0.78, ΔBIC 575, on an axis that had none). Identified with the geometric effects held, the loops
    are the trace's without them. Where only geometric effects were named and those loops name other geometric
    ones, with less left (a bow where a squareness, its slope, was held: an independent rigid bow of 11 µm over 400
    mm, 0.357 → 0.219 µm in 0.215 µm of noise), the loops are identified once more around these, and kept where
    they name them again.
    """
    geometric = tuple(e for e in result.effects if e.stage == "geometry")
    if not geometric:
        return result, near
    alone = len(geometric) == len(result.effects)
    held = geometric
    again, near_again = _identified_again(trace, held, max_effects, say)
    if again is None:
        return replace(result, warnings=result.warnings + (near_again,)), near
    swapped = ""
    if (alone and _labels(again.effects) != _labels(held) and again.effects
            and all(e.stage == "geometry" for e in again.effects) and again.steps[-1].rms_um < result.steps[-1].rms_um):
        # on those loops other geometric effects are named (a look-alike of what was held): the loops identified
        # once more around these are kept where they name them again, loops and effects agreeing
        retry, near_retry = _identified_again(trace, again.effects, max_effects, say)
        if retry is not None and _labels(retry.effects) == _labels(again.effects):
            swapped = (f"; identified with {', '.join(e.label for e in held)} held, the loops named "
                       f"{', '.join(e.label for e in again.effects)} instead, and again with that held")
            held, again, near_again = again.effects, retry, near_retry
    kept = _labels(again.effects) == _labels(held) if alone else len(again.effects) < len(result.effects)
    if not kept or again.steps[-1].rms_um > result.steps[-1].rms_um:
        return result, near
    labels = ", ".join(e.label for e in held)
    it = "them" if len(held) > 1 else "it"
    left = f"{result.steps[-1].rms_um:.4g} µm RMS left; now {again.steps[-1].rms_um:.4g} µm"
    dropped = ", ".join(e.label for e in result.effects if e.label not in _labels(again.effects))
    said = f" ({left}{swapped})" if alone else f", and {dropped} named on them took that up ({left} with fewer effects)"
    return replace(again, warnings=again.warnings + (
        f"the servo loops were identified again with {labels} held in place: identified with {it} in the trace, they "
        f"had bent to {it}{said}",)), near_again


def _labels(effects):
    """The labels of `effects`, as a set."""
    return {e.label for e in effects}


def _identified_again(trace, held, max_effects, say, loops=None):
    """The diagnosis on loops identified again with the effects `held` in place: ``(Diagnosis, near)`` as
    :func:`_diagnose`'s, or ``(None, warning)`` where that fails. Where such `loops` are given (a held search's), the
    diagnosis on them, if it names the first of `held` there; else on loops identified anew by the staged search (an
    independent rigid feedback delay of 0.23 ms, held at 0.31 ms: not named on the search's loops, one fit from the
    loops bent to it; named on the staged search's, 0.33 µm left)."""
    labels = ", ".join(e.label for e in held)
    try:
        if loops is not None:
            say(f"diagnosing on the servo loops identified with {labels} held in place")
            found = _diagnose(trace, Model(loops), True, max_effects, say)
            if (held[0].name, held[0].axis) in {(e.name, e.axis) for e in found[0].effects}:
                return found
        say(f"identifying the servo loops again with {labels} held in place")
        return _diagnose(trace, Model(identify_machine(trace, progress=say, effects=held)), True, max_effects, say)
    except _FIT_FAILURES as exc:
        return None, f"identifying the servo loops again with {labels} in place failed ({exc})"


def _diagnose(trace, model, identified, max_effects, say):
    """One diagnosis of `trace` against the nominal `model` (`identified` from the trace or given): :func:`diagnose`.

    Returns ``(Diagnosis, fits)``, `fits` the candidates of the round that found nothing significant to name, fitted,
    best first (empty where the rounds stopped otherwise).
    """
    missing = [a for a in trace.axes if a not in model.machine.axes]
    if missing:
        raise ValueError(f"the model has no servo axis {missing[0]!r} for the trace's column {missing[0]!r}; "
                         f"its axes are {', '.join(model.machine.axes)}")
    model, warnings = (model, []) if identified else _stable_start(model, trace.axes)
    _within_max_feed(trace, model.machine)
    if trace.dt > _SLOWEST_LOG:
        warnings.append(f"the trace is sampled every {1e3 * trace.dt:.4g} ms, slower than a position loop lags (1/kp, "
                        "10–100 ms): the loops' dynamics are not resolved; check the time unit (e.g. a line "
                        "'# units: t [ms]')")
    reference = measured_reference(trace, model.machine.servo_period)
    # a known force in N has no scale on an identified machine (its mass is assumed): used with a given model only
    force = {} if identified else measured_force(trace, model.machine.servo_period)
    before = _on_trace(trace, reference.t, simulate_batch([model], reference, settle=0.0, check=not identified,
                                                          force=force)["tool_position"][0])
    cycles = standstill_cycles(trace, reference, trace.actual - before)
    noise = noise_level(trace.actual - before, trace.actual)
    for i, cycle in cycles.items():  # the noise is what is white: a limit cycle is left out of its estimate
        quiet = ~cycle["samples"]
        if quiet.sum() >= _FEWEST_SAMPLES:
            noise[i] = noise_level((trace.actual - before)[quiet, i:i + 1], trace.actual[quiet, i:i + 1])[0]
    scored = np.ones(len(trace.t), bool)
    speed = np.linalg.norm(reference.velocity, axis=1)
    if speed[0] > 1e-3 * speed.max():
        # the simulation starts at rest on the reference, the machine did not: leave its transient out
        skip = min(5.0 * max(_settling_time(model.machine.axes[a]) for a in trace.axes), 0.1 * (trace.t[-1] - trace.t[0]))
        scored = trace.t >= trace.t[0] + skip
        warnings.append(f"the trace does not start at rest on its reference: the first {skip:.3g} s "
                        "(five time constants of the slowest closed-loop pole) are left out of the fit and the figures")
    if identified:
        warnings.append("the nominal machine was identified from the trace with an assumed mass "
                        "(forces such as force_N are relative to that axis, not in real newtons)")
    if not np.any(np.ptp(trace.reference, axis=0) > 0):
        warnings.append("the trace's reference never moves: " + (
            "its servo loops cannot be identified from it (it is compared with axes standing still: hunting and drift "
            "show, loop effects cannot); give the nominal model (--model)" if identified else
            "hunting and drift of axes standing still show, the loop and geometry effects that need motion cannot"))
    if identified and trace.force:
        warnings.append(f"the trace's force column(s) ({', '.join(f'{a}_force' for a in trace.force)}) are not used: "
                        "a force in newtons has no scale on an identified machine; give the nominal model (--model)")
    if len(trace.axes) == 1:
        warnings.append("one axis: gain_mismatch cannot be told from the nominal position gain and is not a candidate")
    nominal_current = _currents(trace, model, reference, force)
    current_noise = {} if identified else _current_noise(trace, nominal_current, scored, warnings)
    few = int(scored.sum()) < _FEWEST_SAMPLES  # the nominal parameters would fit them by construction: kept
    problem = _Problem(trace, model, noise, scored, identified, force, current_noise, refit=0 if few else _REFIT_STEPS)
    if not (identified or few):
        problem = _integrator_chosen(problem, model, lambda m: _Problem(trace, m, noise, scored, False, force,
                                                                        current_noise), warnings, say)
    raw = (trace.actual - before)[scored]
    steps = [Step("nominal model", None, {}, _rms_um(raw), _max_um(raw), np.nan)]
    # too few samples: the nominal parameters kept, as the row says
    steps.append(Step("nominal refit", None, {}, steps[0].rms_um, steps[0].max_um, np.nan) if few else
                 _step(problem, "nominal refit", None, {}, np.nan))
    where = locate(trace, problem.reference, np.where(scored[:, None], trace.actual - before - raw.mean(axis=0), 0.0))
    both_ways = min(turning(problem.reference.position, problem.reference.velocity)) >= _BOTH_WAYS
    lost = _not_following(trace, before, scored) + _leading(trace, before, scored, noise)
    if few:
        lost.append(f"the trace has {scored.sum()} samples scored: too few to tell its noise floor (from second "
                    f"differences) or to refit the nominal parameters, which would fit them by construction; at least "
                    f"{_FEWEST_SAMPLES} are needed. No effect is named, and the nominal parameters are kept")
    warnings += lost
    disputed = set()  # axes whose measured current did not bear out the friction named on them (said)
    moves = {}  # of each effect named, how far its fit moved as the nominal parameters were refitted around it
    shares = {}  # of each effect named, the share of the gap above the noise floor it closed
    near = []  # the candidates of a round that found nothing significant, fitted
    for round_ in range(0 if lost else max_effects):
        base = problem.base
        rss0 = float(problem.base_residual @ problem.base_residual)
        # at the noise floor, unless the first refit got it there only by bending the plant beyond its prior (it stands
        # for what is missing); with an effect named the refit goes where the trace pulls it on the axes it acts on
        if rss0 <= problem.n * (NOISE_FLOOR if round_ else 1.0) ** 2 and (
                identified or round_ > 0 or not _far_from_prior(problem.nominal, base.machine, trace.axes)):
            say("the residual is at the noise floor: stopping")
            break
        cands = _candidates(problem, base, warnings)
        say(f"[effect {round_ + 1}] starting values of {len(cands)} candidates (one batch)")
        cands = _start(problem, cands, base, warnings)
        cands = [c for c in cands if c.delta_bic > 0]  # no row of its grid explains anything: not refined
        refined = []
        for i, cand in enumerate(cands):
            try:
                _refine(problem, cand, base)
                if cand.effect.name == "backlash":
                    cand = _approached(problem, cand, base)
            except _FIT_FAILURES as exc:
                warnings.append(f"{cand.effect.label}{_options(cand.effect)}: left out, its fit failed ({exc})")
                continue
            if _not_its_kind(problem, cand):
                continue
            refined.append(cand)
            say(f"[effect {round_ + 1}, {i + 1}/{len(cands)}] {cand.effect.label:<22}"
                f"{_options(cand.effect):<26} RMS {_rms_um(problem.unwhiten(cand.residual)):8.3f} µm")
        cands = refined
        _rescore(problem, cands)
        cands = _acceleration_twins(problem, cands, warnings)
        cands.sort(key=lambda c: -c.delta_bic)
        if cands and cands[0].delta_bic > SIGNIFICANT and not identified:
            cands = _profiled(problem, base, cands, warnings, say)
        if not cands or not cands[0].delta_bic > SIGNIFICANT:
            say("nothing significant left: stopping")
            near = [c.fit for c in cands if c.delta_bic > 0]
            break
        best, ambiguities = _choose(problem, cands, both_ways)
        gap = problem.left()  # what the base leaves, per axis [mm]
        # a friction's force is what a measured current sees directly: fitted with the current as a second output
        # (:data:`CURRENT_FITS`); the candidates are told apart, and the plant refitted, by the positions alone
        current = best.fit.name in CURRENT_FITS and best.fit.axis in problem.current_noise
        try:
            if current:
                best, disagreement = _settled_with_current(problem, base, best)
                if disagreement is not None:
                    warnings.append(disagreement)
                    disputed.add(best.fit.axis)
                current = disagreement is None
            if not current:
                if best.settled is None:
                    best.settled = _settle(problem, base, best)
                else:
                    problem.set_base(best.settled[0])
            warnings += best.settled[1]
        except _FIT_FAILURES as exc:
            warnings.append(f"{best.fit.label}: not named, the refit with it in place failed ({exc})")
            problem.set_base(base)
            break
        if not best.lever > SIGNIFICANT:  # what it closed, the plant refitted around it closes: a lever, not a cause
            warnings.append(f"{best.fit.label}: not named, with the nominal parameters refitted around it its fit is "
                            f"not significant (ΔBIC {best.lever:.3g}, named from {SIGNIFICANT:g}): what it closed, "
                            "the plant refitted around it closes without it")
            problem.set_base(base)
            break
        step = _step(problem, best.fit.label, best.fit, best.uncertainty, best.delta_bic)
        if not step.rms_um < steps[-1].rms_um:  # an effect that does not close any of the gap is no explanation
            warnings.append(f"{best.fit.label}: not named, " + (
                f"its fit does not lower the residual ({steps[-1].rms_um:.4g} -> {step.rms_um:.4g} µm RMS)"
                if np.isfinite(step.rms_um) else "the model with it in place does not follow the trace (its simulation diverged)"))
            problem.set_base(base)
            break
        edge = _size_at_edge(problem, best) or _controller_far_off(problem, best.fit)
        if edge is not None:
            warnings.append(f"{best.fit.label}: not named, {edge}")
            problem.set_base(base)
            break
        # the gap on the axes the effect acts on: another axis's misfit is none of its business
        on = [trace.axes.index(a) for a in _acts_on(best.fit)]
        before_um, after_um = (_rms_um(r[:, on]) for r in (gap, problem.left()))
        floor = float(np.linalg.norm(noise[on])) * 1e3
        share = (before_um**2 - after_um**2) / max(before_um**2 - floor**2, 1e-300)
        if share < GAP_SHARE:  # significant, but a sliver of the gap: model error the effect bends to, not the effect
            warnings.append(f"{best.fit.label}: not named, it closes {share:.0%} of the residual above the noise floor "
                            f"on {_acts_on(best.fit)} ({before_um:.4g} -> {after_um:.4g} µm RMS, floor {floor:.3g} µm; "
                            f"named from {GAP_SHARE:.0%})")
            problem.set_base(base)
            break
        warnings += ambiguities
        shares[best.fit.label] = share
        warnings += _shape_at_edge(problem, best)
        if best.fit.name == "straightness" and best.fit.axis not in base.machine.travel:
            warnings.append(f"{best.fit.label}: the machine gives no travel for axis {best.fit.axis} (travel_mm): the bow "
                            "is fitted over the trace's own extent, its curvature the guideway's, its vertex (the "
                            "middle of the travel, start_mm + span_mm/2) where its slope over the path puts it: a "
                            f"squareness's shear is told from it only by the curvature; to check: {_SLOPE_TEST}")
        untravelled = [a for a in best.fit.axis if a not in base.machine.travel]
        if best.fit.name == "squareness" and untravelled:
            # the straightness candidates then bow over the trace's own extent, their vertex fitted within a few
            # extents of it: a straightness over a travel much longer than the path is its slope there, not weighed
            warnings.append(f"{best.fit.label}: the machine gives no travel for axis {', '.join(untravelled)} "
                            "(travel_mm): a guideway's straightness over the travel shows over a path small against "
                            "it mostly as its slope there, a squareness's shear, and is not told apart from it; to "
                            f"separate them: {_SLOPE_TEST}")
        steps.append(step)
        moves[best.fit.label] = best.moved
        if len(steps) > 3 and not identified:
            say(f"the {len(steps) - 2} effects named refitted each with the others in place")
            steps[2:] = _revisited(problem, steps[2:], disputed, moves, warnings)
            last = steps[-1]  # its residual now the effects' refitted together; the earlier steps' as they were named
            steps[-1] = _step(problem, last.label, last.effect, last.uncertainty, last.delta_bic)
        say(f"named {best.fit!r}: residual RMS {steps[-2].rms_um:.3f} -> {steps[-1].rms_um:.3f} µm")
    named = [f"{s.effect.label}: not named" for s in steps if s.effect is not None]
    warnings = [w for w in warnings if not w.startswith(tuple(named))]  # a round's reason, which a later round overcame
    for step in steps[2:]:  # of the sizes the table gives (the effects refitted each with the others in place)
        undetermined = _size_undetermined(step.effect, step.uncertainty, shares[step.label])
        warnings += ([] if undetermined is None else [undetermined]) + _atypical(step.effect, identified)
    if len(steps) == 2 and not (lost or identified):  # nothing named: the plant where the trace pulls it, past the first reach
        problem.set_base(problem.base, refit=_REFIT_STEPS)
        steps[1] = _step(problem, "nominal refit", None, {}, np.nan)
    if identified and len(trace.axes) == 2:
        for step in steps:
            if step.effect is not None and step.effect.name == "gain_mismatch":
                other = next(a for a in trace.axes if a != step.effect.axis)
                warnings.append(f"{step.effect.label}: with one position gain identified for both axes only the ratio of "
                                f"their gains is known; kp_ratio {step.effect['kp_ratio']:.4g} on "
                                f"{step.effect.axis} is the same machine as {1.0 / step.effect['kp_ratio']:.4g} on {other}")
            elif step.effect is not None and step.effect.name == "time_delay":
                warnings += _delay_as_ratio(step.effect, problem.base.machine.axes[step.effect.axis].kp,
                                            next(a for a in trace.axes if a != step.effect.axis))
    if identified:
        warnings += identification_warnings(model.machine, problem.base.machine)
        moving = int(np.sum(np.ptp(trace.reference, axis=0) > 0))
        if len(steps) == 2 and not both_ways and moving >= 2 and steps[-1].rms_um > NOISE_FLOOR * 1e3 * float(
                np.linalg.norm(noise)):
            warnings.append("nothing named on loops identified from a path run one way: on a circle a squareness or a "
                            "scale error of its axes is a difference of the axes' lags (an error ∝ y is ∝ x's "
                            "velocity there, one ∝ x is ∝ x's acceleration), which the loops take up; to tell them "
                            "apart: the path run the other way too (CW and CCW, as a ballbar test does), or the data "
                            "sheet (diagnose --model)")
    else:
        warnings += _far_from_prior(problem.nominal, problem.base.machine, trace.axes)
        refused = problem.base.machine.refusal(trace.axes)
        if refused is not None:
            warnings.append(f"the refitted plant's loops fail the loop check ({refused}): the corrected model is read "
                            "by diagnose --model; simulate and compare refuse it")
    written = _rms_um(problem.as_written())  # what the corrected model, simulated as written, leaves
    if written > _AS_WRITTEN * steps[-1].rms_um and written - steps[-1].rms_um > 0.1e3 * float(np.linalg.norm(noise)):
        # (a gap under a tenth of the noise is none to speak of: a still trace's 5e-16 against 4e-16 µm was said)
        warnings.append(f"the corrected model as written leaves {written:.4g} µm RMS on this trace (the instrument's "
                        f"zero and turn taken out), not the {steps[-1].rms_um:.4g} µm of the last row: each row adds a "
                        f"refit of the plant linearised around it ({100 * _NUISANCE_STEP:g} % steps of each "
                        "parameter), which the plant simulated where that refit points does not bear out (a friction's "
                        "or backlash's contacts, a plant pulled far from its data sheet)")
    after = problem.fitted()
    left = unexplained(trace, problem.reference, np.where(scored[:, None], trace.actual - after, 0.0), noise, scored)
    warnings += [f"hunting at standstill on {trace.axes[i]}: a limit cycle of ±{1e3 * c['amplitude']:.3g} µm at "
                 f"{c['frequency']:.3g} Hz while the reference stands still (not noise); a loop with integral action "
                 "hunts against a backlash or a stick-slip friction (more so closed on a linear scale), or a few "
                 "encoder counts: no simulation matches its phase sample by sample, a named effect closes little of it"
                 for i, c in cycles.items()]
    currents = [nominal_current, _currents(trace, problem.base, reference, force)]
    for a in [a for a in problem.current_noise if a not in disputed]:  # does the current agree with the refit plant?
        was, now = (float(np.sqrt(np.mean((trace.current[a] - c[a])[scored] ** 2))) for c in currents)
        if now > _CURRENT_WORSE * was and now - was > 0.01 * float(np.std(trace.current[a][scored])):
            warnings.append(f"{a}: the refitted model's current is further from the measured one than the nominal "
                            f"model's ({was:.3g} -> {now:.3g} A RMS): the positions pulled the plant (mass, damping) "
                            "where the current does not follow; take the refitted plant for a fit, not for the machine's")
    return Diagnosis(trace, model, identified, 1e3 * noise, 1e3 * problem.zero_offset(), tuple(steps), before, after,
                     scored, problem.base, where, tuple(warnings), tuple(left), *currents), near


def _within_max_feed(trace, machine):
    """Refuse a trace whose commanded positions move faster than `machine`'s max feed from one sample to the next
    (the simulation, which refuses such a reference, would say it of a path planned too fast), naming where."""
    if machine.max_feed is None:
        return
    moved = np.linalg.norm(np.diff(trace.reference, axis=0), axis=1)
    speed = moved / np.diff(trace.t)
    k = int(np.argmax(speed))
    if speed[k] > machine.max_feed * (1 + 1e-6):
        refs = ", ".join(f"{a}_ref" for a in trace.axes)
        raise ValueError(f"the trace's commanded position ({refs}) moves {moved[k]:.6g} mm from sample {k + 1} to "
                         f"{k + 2} (t = {trace.t[k]:.6g} to {trace.t[k + 1]:.6g} s), {60 * speed[k]:.6g} mm/min, above "
                         f"the machine's max feed {60 * machine.max_feed:.6g} mm/min: a jump in the log (a lost or "
                         "spliced sample?), or, if the machine ran that fast (a feed override), the model's "
                         "max_feed_mm_min is too low")


def _integrator_chosen(problem, model, build, warnings, say):
    """`problem`, of the given `model`, or the problem `build` makes of `model` with the rule its velocity PIs
    integrate by that the trace follows best, where it does not give it (``velocity_integrator``; said in `warnings`).

    Drives differ in how their sampled PI integrates, and a data sheet rarely says: the rules differ by
    ``dt/(2·ti)`` of the proportional gain (:data:`~contoursim.servo.VELOCITY_INTEGRATORS`), about 1 % on a velocity
    loop, which shows wherever the path accelerates. An independent simulator's drives update the integral with the
    present error (the backward rule): against the trapezoidal rule, the kernel's with nothing said, the same machine
    with its data sheet exact left a misfit of 0.48 µm at a circle's start and stop in 0.26 µm of noise, to which a
    gain mismatch of 0.99 was fitted (ΔBIC 70). One rule for all axes (one firmware, as :func:`identify_machine`
    takes one drive structure), each problem refitted around it; another than the trapezoidal rule is chosen when its
    ΔBIC, the choice counted as one parameter, is significant.
    """
    machine = model.machine
    axes = [a for a in problem.trace.axes if machine.axes[a].ti is not None and machine.axes[a].velocity_integrator is None]
    if not axes:
        return problem
    rss0 = float(problem.base_residual @ problem.base_residual)
    tau = autocorrelation_time(problem.samples(problem.base_residual)[problem.scored])
    best, gain = problem, SIGNIFICANT
    for rule in (r for r in VELOCITY_INTEGRATORS if r != "tustin"):
        say(f"the velocity PI integrated by the {rule} rule")
        try:
            other = build(_with_servos(model, {a: {"velocity_integrator": rule} for a in axes}))
        except _FIT_FAILURES:
            continue
        better = float(delta_bic(rss0, float(other.base_residual @ other.base_residual), problem.n, 1, tau))
        if better > gain:
            best, gain = other, better
    if best is not problem:
        rule = best.base.machine.axes[axes[0]].velocity_integrator
        warnings.append(f"the machine does not say how the velocity PI of {', '.join(axes)} integrates "
                        f"(velocity_integrator): the trace follows the {rule} rule best (ΔBIC {gain:.3g} over the "
                        "trapezoidal rule simulated where none is given); the refit and the corrected model take it")
    return best


def _acts_on(effect):
    """The axes whose positions `effect` moves: a straightness's error direction, else the axes it is named on."""
    return effect.options["error_direction"] if effect.name == "straightness" else effect.axis


def _size_at_edge(problem, cand):
    """Why `cand`'s fitted size does not stand for the effect, or ``None``: at an edge of the range the fit may take
    (other than no effect), the trace asking for more than the effect can be: something else it is bent to."""
    size = cand.fit.parameters[0]
    if size.name not in cand.free:
        return None
    lower, upper = (b[cand.free.index(size.name)] for b in _bounds(problem, cand))
    none = effect_kind(cand.fit.name).parameters[0].value
    if any(b != none and _at(size.value, b) for b in (lower, upper)):
        return f"its {size.name} = {size.value:.4g} is at the edge of the range the fit may take ({lower:.4g}–{upper:.4g})"
    return None


def _not_its_kind(problem, cand):
    """Whether a refined `cand` fits a shape its kind does not have (left out of the candidates): a cyclic error whose
    period ran to the stroke, a bow whose vertex ran away from the path or whose sag the trace does not pin down, or a
    vibration that is no lightly damped mode.

    A cyclic error repeats along the stroke; fitted at a period as long as the stroke allows (:func:`_bounds`: at
    least one period within it), it is one slow wave, a bow or a slope in disguise: the independent rigid seed-14
    backlash started closed, after the backlash, had a cyclic error of x named at 109 mm (its whole stroke) beside
    it, fitted to the misfit of a plant off by a few percent.

    A straightness fitted with its vertex (:func:`_bow_grid`) as far from the path as the fit may take it, or with its
    sag over the path within 2σ of none, is a slope with no curvature the trace holds: a large delay of y's command
    on a one-way circle, on identified loops, was fitted so (a peak of 7.8 ± 19 µm, the vertex at the limit) and named
    before the delay; beside a gain mismatch on the own kernel's ISO 230-4 circle, a sag of 0.047 ± 0.042 µm was
    named, the slope taking up the identified loops' misfit (0.351 µm left where, without it, 0.156).

    A vibration's damping ratio runs to the bound :data:`_MODE_DAMPING_MAX`: a filter in disguise. Or, on identified loops, its
    1σ spans the whole range the fit may take: a mode shows in a trace as its ringing after the path's jerks, and the
    ringing's decay is its damping; where the fit cannot tell a damping ratio of 0.0001 from 0.35, no ringing is seen,
    the candidate fitting only a resonance's gain and phase at the path's own frequencies, which the identified loops'
    own misfit draws as well. Beside the effect named first on identified loops (independent rigid and two-mass
    traces, 7 of 132 cases over six seeds) such candidates were named at a 1σ of 0.38–6.5; the modes hidden in 27
    traces (own, rigid and two-mass, three seeds) and named without the model, in 5, at 0.076–0.18. With the data
    sheet the loops are known and a weak mode may show only so: true ones were named at up to 0.48 (a 56 Hz mode of
    0.63 µm in 0.27 µm of noise, fitted at 62 ± 5 Hz), and the false ones above arose on identified loops only.
    """
    if cand.fit.name == "cyclic_error" and "period_mm" in cand.free:
        return _at(cand.fit["period_mm"], _bounds(problem, cand)[1][cand.free.index("period_mm")])
    if cand.fit.name == "straightness" and "start_mm" in cand.free:
        j = cand.free.index("start_mm")
        flat = abs(cand.fit["peak_um"]) < 2.0 * cand.uncertainty.get("peak_um", np.inf)
        return flat or any(_at(cand.fit["start_mm"], b[j]) for b in _bounds(problem, cand))
    if cand.fit.name != "vibration":
        return False
    if cand.fit["damping_ratio"] >= 0.99 * _MODE_DAMPING_MAX:
        return True
    if not problem.identified:
        return False
    lower, upper = (b[cand.free.index("damping_ratio")] for b in _bounds(problem, cand))
    return cand.uncertainty.get("damping_ratio", 0.0) > upper - lower


def _controller_far_off(problem, effect):
    """Why `effect` does not stand for what the trace shows, or ``None``: it departs from a controller setting the
    model gives exactly (:func:`_departs_from`) by more than the catalogue's typical size (a ``kp_ratio`` beyond
    0.7–1.3, a delay beyond 3 ms). A data sheet's software constant is not that far off; a fit that asks for it is
    bent to something the catalogue lacks (an independent axis's Stribeck friction at full feedforward, with its
    Coulomb part named, was followed by a ``kp_ratio`` of 1.47 ± 0.14)."""
    setting = _departs_from(problem, effect)
    size = effect.parameters[0]
    lo, hi = size.typical
    short = effect.name == "time_delay" and size.value < lo  # a delay shorter than typical is as plausible as one typical
    if setting is None or lo <= size.value <= hi or short:
        return None
    unit = "" if size.unit == "-" else f" {size.unit}"
    return (f"its {size.name} = {size.value:.4g} lies beyond the typical {lo:g}–{hi:g}{unit}, and the model gives "
            f"{setting} exactly: a controller set that far from its data sheet is not a plant a few % off; the trace "
            "asks for something the catalogue lacks (see the unexplained structure). If the setting may be otherwise, "
            "list it in the machine file's uncertain = [...] of that axis")


def _at(value, bound):
    """Whether a fitted `value` ran to its finite `bound`."""
    return bool(np.isfinite(bound) and abs(value - bound) <= 1e-6 * max(abs(bound), 1e-12))


def _shape_at_edge(problem, cand):
    """What to say of a named effect's free parameters other than its size that ran to an edge of the range the fit
    may take (a mode's damping ratio at its floor): the trace does not pin them down, the size may stand."""
    lower, upper = _bounds(problem, cand)
    said = []
    for name, low, high in zip(cand.free, lower, upper):
        value = cand.fit[name]
        if name != cand.fit.parameters[0].name and (_at(value, low) or _at(value, high)):
            said.append(f"{cand.fit.label}: its {name} = {value:.4g} is at the edge of the range the fit may take "
                        f"({low:.4g}–{high:.4g}): the trace does not pin it down (the parameters held at a default, "
                        "such as a mode's mass ratio, may be bent to it)")
    return said


def _size_undetermined(effect, uncertainty, share):
    """What to say of a named `effect` whose size lies within twice its `uncertainty` (1σ by parameter) of no effect
    (it closes `share` of the gap: the effect is there, its size is not pinned down), or ``None``. A vibration's first
    parameter is its frequency, not a size: not judged."""
    size = effect.parameters[0]
    sigma = uncertainty.get(size.name)
    none = effect_kind(effect.name).parameters[0].value
    if effect.name == "vibration" or sigma is None or abs(size.value - none) >= 2.0 * sigma:
        return None
    return (f"{effect.label}: named, it closes {share:.0%} of the residual above the noise floor on {_acts_on(effect)}, "
            f"but its {size.name} = {size.value:.4g} ± {sigma:.2g} (1σ) lies within 2σ of none ({none:g}): the trace "
            "does not pin its size down (model error the uncertainty counts: see uncertainty_method)")


def _atypical(effect, identified):
    """What to say of a named `effect` whose size lies beyond the catalogue's typical range, further from no effect
    than machines typically show (a list of one sentence, or empty); one nearer to no effect (a squareness of 17 µrad
    against a typical 20–200) is a machine in good order (an outside tester's friction of 60 N was named, without the
    model, as a backlash of 172 µm read on a scale). A vibration's first parameter is its frequency, not a size;
    a force fitted on an `identified` machine is in the units of its assumed mass, not in newtons: neither judged."""
    size = effect.parameters[0]
    if effect.name == "vibration" or size.typical is None or (identified and size.unit == "N"):
        return []
    lo, hi = size.typical
    value = abs(size.value) if size.signed else size.value
    none = effect_kind(effect.name).parameters[0].value
    if not ((value > hi and hi >= none) or (value < lo and lo <= none)):
        return []
    unit = "" if size.unit == "-" else f" {size.unit}"
    return [f"{effect.label}: its {size.name} = {size.value:.4g} lies beyond what machines typically show ({lo:g}–{hi:g}"
            f"{unit}): measure it directly before acting on it; the trace may hold something the catalogue lacks, "
            "which this effect was bent to"]


def _current_noise(trace, simulated, scored, warnings):
    """The noise level of each measured current the fit may take as an output [A], by axis (:func:`noise_level` of
    the nominal model's misfit, `simulated` its currents).

    A current the nominal model does not follow is left out, said in
    `warnings`: its misfit wider than its own spread, or its scale against
    the simulated current (the least-squares gain through zero) outside
    :data:`_CURRENT_SCALE`: negative (the other sign), or a hundred times
    or more (a current logged in mA: one whose mean is near zero has a
    misfit just under its spread, 134.38 against 134.39 A, and a gain of
    2,600). A friction the model lacks raises that gain too, by the
    friction's share of the force (an independent square path's: 2.5 and
    4.2), so the bound is wide.
    """
    out = {}
    if scored.sum() < 3:  # no second differences: the diagnosis says the trace has too few samples scored
        return out
    for a, y in simulated.items():
        measured = trace.current[a][scored]
        misfit = measured - y[scored]
        rms, spread = float(np.sqrt(np.mean(misfit**2))), float(np.std(measured))
        gain = float(measured @ y[scored]) / max(float(y[scored] @ y[scored]), 1e-300)
        if not (rms < spread and _CURRENT_SCALE[0] < gain < _CURRENT_SCALE[1]):
            warnings.append(f"{a}_current: not fitted, the nominal model does not follow it (its misfit {rms:.3g} A RMS "
                            f"against a spread of {spread:.3g} A; it is {gain:.3g} times the simulated current): check "
                            "its unit, its sign and that it is the current command (a force constant in N/A)")
            continue
        out[a] = float(noise_level(misfit[:, None], measured[:, None])[0])
    return out


def _currents(trace, model, reference, force):
    """`model`'s current commands at the trace's samples for the axes whose current the trace measured [A], by axis
    (the nominal loop was checked by the first simulation)."""
    if not trace.current:
        return {}
    run = simulate_batch([model], reference, outputs=("current",), settle=0.0, check=False, force=force)["current"][0]
    names = list(model.machine.axes)
    return {a: _on_trace(trace, reference.t, run[:, [names.index(a)]])[:, 0] for a in trace.current}


def _settle(problem, base, best, current=False):
    """Make `base` with `best`'s effect the problem's base: nominal parameters refitted with it in place, then the
    effect refitted around them (with `current`, the measured currents its second output), then the nominal
    parameters again. Returns ``(the new base, warnings it brings)``; `best.lever` is then its ΔBIC on the refitted
    plant against that plant without it (not significant: the refit, not the effect, closed the gap)."""
    reach = _reach(problem, [*base.effects, best.fit])
    problem.set_base(_with_effect(base, best.fit), refit=_REFIT_STEPS, **reach)
    problem.set_base(Model(problem.base.machine, base.effects))
    problem.use_currents(current)
    try:
        best.x = np.array([best.fit[name] for name in best.free])
        _refine(problem, best, problem.base)
        # how far the fit moved with the nominal parameters refitted around it: how much it hangs on a plant known
        # only to its prior, model error the residual of either fit cannot show
        moved = {name: abs(best.fit[name] - x) for name, x in zip(best.free, best.x)}
        if best.moved:  # settled before, the plant refitted then from its prior and now from there: the most it moved
            moved = {name: max(m, best.moved.get(name, 0.0)) for name, m in moved.items()}
        best.moved = moved
        best.lever = best.delta_bic
        if best.fit.name == "coulomb_friction":
            _with_stribeck(problem, best, problem.base)
    finally:
        problem.use_currents(False)
    best.uncertainty = {name: float(np.hypot(e, moved.get(name, 0.0))) for name, e in best.uncertainty.items()}
    problem.set_base(_with_effect(problem.base, best.fit), refit=_REFIT_STEPS, **reach)
    said = []
    if best.fit.name == "coulomb_friction" and base.machine.axes[best.fit.axis].ti is None:
        best.fit = _constant_force(problem, best.fit)
        problem.set_base(_with_effect(problem.base, best.fit))
        said.append(f"{best.fit.label}: offset_N is the constant force that shifts the axis as far as the "
                    "measurement's zero offset; without an integrator in the velocity loop the two "
                    "cannot be told apart")
    return problem.base, said


def _reach(problem, effects):
    """How far the nominal refit with `effects` in place goes (:meth:`_Problem.set_base`): the plant of an axis they
    act on where the trace pulls it; another axis's no further than :data:`_PRIOR_REACH`, as before any effect is
    named (pulled further, it takes up what is still missing there and hides it from the candidates screened next: an
    independent two-mass Y's backlash of 6.4 µm bent Y's screw 12 prior widths as a scale error of X was named, and
    what it left, 16 % of the gap, was not named). An identified machine's loops go where the trace pulls them."""
    if problem.identified:
        return {}
    return dict(reach=_PRIOR_REACH, free={a for e in effects for a in e.axis + _acts_on(e)})


def _revisited(problem, named, disputed, moves, warnings):
    """The steps `named` with each effect refitted with the others in place: its fit and uncertainty.

    An effect is fitted while the effects named after it are missing, and
    it takes up what it can of them: where both axes of an independent
    LuGre drive had a friction, the one named first came out at 107.6 N
    against 90.9 N, without its Stribeck part and with its axis's damping
    refitted to a fifteenth of its data sheet's, where the same axis alone fitted
    89.5 N with it; the one named after it then fitted against that. Each,
    in the order named, is settled again (:func:`_settle`: the nominal
    parameters refitted around it, the measured current as the second
    output where it bore the effect out when it was named) on the base
    with all the others; the refit is kept unless it leaves the positions
    further from the trace (a friction fitted with its current: by more
    than :data:`_CURRENT_TOLERANCE`), the effect as named otherwise. Its
    uncertainty keeps the most its fit moved as the nominal parameters
    were refitted around it (`moves`, by label; updated): settled again,
    the plant is refitted from where the first settling left it, not from
    its prior, and moves less, though the fit hangs on it as much (an
    independent two-mass backlash of 6.22 µm, fitted at 5.66 µm beside a
    scale error, came out ± 0.21 µm counting only the second move).
    """
    revisited = []
    for step in named:
        base, label = problem.base, step.effect.label
        was = _rms_um(problem.left())
        current = (step.effect.name in CURRENT_FITS and step.effect.axis in problem.current_noise
                   and step.effect.axis not in disputed)
        cand = _Candidate(step.effect, tuple(step.uncertainty), [], fit=step.effect, uncertainty=dict(step.uncertainty),
                          moved=moves[label])
        try:
            _, said = _settle(problem, Model(base.machine, tuple(e for e in base.effects if e.label != label)), cand,
                              current)
        except _FIT_FAILURES as exc:
            warnings.append(f"{label}: kept as named, its refit with the other effects named in place failed ({exc})")
            said = None
        if said is None or not _rms_um(problem.left()) <= (_CURRENT_TOLERANCE if current else 1.0) * was:
            problem.set_base(base)
            revisited.append(step)
            continue
        warnings += [w for w in said if w not in warnings]
        moves[label] = cand.moved
        revisited.append(replace(step, effect=cand.fit, uncertainty=cand.uncertainty))
    return revisited


def _settled_with_current(problem, base, best):
    """`best`, a friction, settled with its axis's measured current as a second output of its fit, where the current
    bears it out: ``(best, None)``; else ``(best as it was, why)``, to be settled from the positions alone.

    The current bears it out where its fit with it is significant (ΔBIC
    above :data:`SIGNIFICANT`) and leaves the positions within
    :data:`_CURRENT_TOLERANCE` of what the positions alone leave (RMS): the
    current may choose among fits the positions find about as good, not
    overrule them. An outside probe's square paths, whose axes stand still
    for long stretches holding a current its friction law at standstill
    sets and the kernel's does not, had a friction named at ΔBIC −1.5 with
    the current, and a LuGre friction of 48.8 N fitted at 71.3 N leaving
    3.8 µm RMS where the positions alone fitted 49.1 N and left 0.92 µm.
    """
    alone = copy.copy(best)
    best.settled = _settle(problem, base, best, current=True)
    if not best.delta_bic > SIGNIFICANT:
        why = f"with the measured current as well its fit is not significant (ΔBIC {best.delta_bic:.3g})"
    else:
        leaves = _rms_um(problem.left())
        if alone.settled is None:
            alone.settled = _settle(problem, base, alone)
        else:
            problem.set_base(alone.settled[0])
        alone_leaves = _rms_um(problem.left())
        if leaves <= _CURRENT_TOLERANCE * alone_leaves:
            problem.set_base(best.settled[0])
            return best, None
        why = (f"fitted with the measured current as well it leaves the positions {leaves:.3g} µm RMS, against "
               f"{alone_leaves:.3g} µm fitted from them alone")
    return alone, (f"{alone.fit.label}: fitted from the positions alone; {why}: the current does not bear it out "
                   "(a friction at standstill the model does not follow?)")


def _with_stribeck(problem, cand, model):
    """`cand`, a Coulomb friction fitted on `model`, fitted again with a Stribeck part where the trace asks for one.

    A friction that breaks away above its sliding level (``stribeck_N``,
    decaying over ``stribeck_velocity_mm_s``) is fitted by a Coulomb level
    alone as the level between the two: an independent LuGre friction of
    120 N sliding and 1.1–1.5 times that at rest came out at 142–149 N. The
    Stribeck part's two parameters, started from a grid of shares and
    speeds, are kept when they earn their place (a ΔBIC above
    :data:`SIGNIFICANT` over the Coulomb level alone, counted with the
    same autocorrelation time); `cand` then takes that fit (in place).
    """
    if "stribeck_N" in cand.free:  # fitted with it already (settled once more: with the current)
        return
    force = cand.fit["force_N"]
    grid = [{"force_N": force * (1.0 - share), "stribeck_N": force * share, "stribeck_velocity_mm_s": v}
            for share in (0.1, 0.3) for v in (0.5, 2.0, 8.0)]
    trial = _Candidate(cand.fit, cand.free + ("stribeck_N", "stribeck_velocity_mm_s"), grid)
    if not _start(problem, [trial], model, []):
        return
    try:
        _refine(problem, trial, model)
    except _FIT_FAILURES:
        return
    if delta_bic(cand.cost, trial.cost, problem.n, 2, cand.tau) > SIGNIFICANT:
        _score(problem, trial, trial.residual, cand.tau)
        for name in ("free", "x", "residual", "cost", "fit", "uncertainty", "delta_bic", "tau"):
            setattr(cand, name, getattr(trial, name))


def _profiled(problem, base, cands, warnings, say):
    """`cands` (sorted best first) with the contenders ranked by their profile over the nominal parameters.

    A candidate is scored on the base's nominal parameters, refitted
    linearly around them; where a large effect is missing, the refit before
    any effect has bent them towards it (a plant several prior widths off),
    and the candidate that best suits the bent plant need not be the one that
    explains the trace. So the contenders, the first :data:`_CONTENDERS`
    closing at least :data:`_CONTENDER_SHARE` of what the best closes, and
    the first-order twin of each (:func:`_partner`), are each settled
    (:func:`_settle`: the nominal parameters refitted with it in place, their
    prior included) and scored again on what they then leave: a profile
    likelihood over the nominal parameters. A contender whose settling fails
    is left out, with a warning: it could not be named.

    With a given model only: on an identified machine the nominal parameters
    are the loops themselves, and their refit from a contender's start runs
    along the valley of position gain against feedforward to wherever it
    stops (a gain mismatch left at eight noise levels where its first-order
    twin, a delay, reached the noise); the loops are identified again with
    the effects in place instead (:func:`diagnose`).
    """
    rss0 = float(problem.base_residual @ problem.base_residual)
    closed = rss0 - cands[0].cost
    contenders = [c for c in cands[:_CONTENDERS] if rss0 - c.cost >= _CONTENDER_SHARE * closed]
    contenders += [t for t in (_partner(c, cands) for c in contenders) if t is not None and t not in contenders]
    if len(contenders) < 2:
        return cands
    say(f"{len(contenders)} contenders ({', '.join(c.fit.label for c in contenders)}): the nominal parameters refitted "
        "around each")
    settled = []
    for cand in contenders:
        try:
            cand.settled = _settle(problem, base, cand)
        except _FIT_FAILURES as exc:
            warnings.append(f"{cand.fit.label}{_options(cand.fit)}: left out, the refit with it in place failed ({exc})")
        else:
            cand.residual = problem.base_residual
            settled.append(cand)
        problem.set_base(base)
    _rescore(problem, settled)
    return sorted(settled, key=lambda c: -c.delta_bic) + [c for c in cands if c not in contenders]


def _settling_time(servo):
    """Time constant of the slowest pole of an axis's closed position loop [s]."""
    from .servo import closed_loop

    return 1.0 / float(np.min(-np.real(closed_loop(servo, feedforward=False).poles())))


def _constant_force(problem, effect):
    """`effect` (friction on an axis without velocity integrator) with ``offset_N`` = the force equal to the zero offset."""
    base = problem.base
    i = problem.trace.axes.index(effect.axis)
    pushed, = problem.predict([base.with_effect(effect.with_values(offset_N=effect["offset_N"] + 1.0))])
    gain = float(np.mean((pushed - problem.base_prediction)[problem.scored, i]))  # [mm/N]
    return effect.with_values(offset_N=effect["offset_N"] + problem.zero_offset()[i] / gain)


def _step(problem, label, effect, uncertainty, delta_bic):
    """The step after `problem`'s base was set: residual RMS and max on the scored samples."""
    r = problem.left()
    return Step(label, effect, uncertainty, _rms_um(r), _max_um(r), float(delta_bic))


def _options(effect):
    options = effect.set_options()
    return "" if not options else " (" + ", ".join(f"{k} = {v}" for k, v in options.items()) + ")"


def synthetic_trace(model, trajectory, mismatch=0.03, noise_um=0.1, quantum_um=0.05, every=1, seed=0):
    """A trace as a real machine would log it: `model` with its nominal parameters a little off, noise, quantisation.

    What the diagnosis is tested on: the "truth" is `model` (a nominal
    machine plus hidden effects) with every axis's plant — mass, force
    constant and damping — scaled by independent factors uniform in
    ``1 ± mismatch`` (the controller's settings are software: exact); the
    recorded positions carry Gaussian noise and are rounded to `quantum_um`.

    Parameters
    ----------
    model : Model or Machine
        The truth before the nominal parameters' spread.
    trajectory : contoursim.trajectory.Trajectory
        The reference, sampled at the machine's servo period.
    mismatch : float
        Relative spread of the nominal parameters [-].
    noise_um : float
        Measurement noise [µm RMS].
    quantum_um : float
        Resolution of the recorded positions [µm] (0: none).
    every : int
        Log every `every`-th servo sample.
    seed : int
        Seed of the spread and the noise.

    Returns
    -------
    contoursim.traces.Trace
        Axes x, y (, z) as the trajectory's dimension.
    """
    from .simulation import simulate
    from .traces import Trace

    model = as_model(model)
    rng = np.random.default_rng(seed)
    machine = model.machine
    factor = lambda: 1.0 + rng.uniform(-mismatch, mismatch)  # noqa: E731
    servos = {a: replace(s, mass=s.mass * factor(), force_constant=s.force_constant * factor(), damping=s.damping * factor())
              for a, s in machine.axes.items()}
    truth = Model(replace(machine, axes=servos), model.effects)
    result = simulate(truth, trajectory, contour=False)
    keep = slice(None, None, int(every))
    actual = result.tool_position[keep] + rng.normal(0.0, noise_um * _UM, result.tool_position[keep].shape)
    if quantum_um > 0:
        actual = np.round(actual / (quantum_um * _UM)) * (quantum_um * _UM)
    axes = ("x", "y", "z")[: trajectory.dim]
    return Trace(result.trajectory.t[keep], result.trajectory.position[keep], actual, axes, {"synthetic": "true"})


# -- figures -----------------------------------------------------------------------------------

def _after(diagnosis):
    """Legend label of the final model."""
    return "after: " + (", ".join(e.label for e in diagnosis.effects) or "nominal refit only")


# "before" a wide light band under the thin "after" line: where they agree, both stay visible
_BEFORE = dict(color="C0", lw=2.6, alpha=0.45, solid_capstyle="butt")
_AFTER = dict(color="C3", lw=0.8)


def plot_residuals(diagnosis, fig=None):
    """Residual over time per axis before (nominal model) and after the diagnosis [µm], with the noise band.

    "Before" is a wide light band under the thin "after" line, the noise
    band's edges (±1σ) dashed over both; the legend sits beside the axes.
    Lines are thinned to what the pixels show, each pixel column's extremes kept
    (:func:`contoursim.plotting.envelope_indices`).

    Parameters
    ----------
    diagnosis : Diagnosis
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    from .plotting import envelope_indices

    trace, keep = diagnosis.trace, diagnosis.scored
    d = len(trace.axes)
    fig = fig or plt.figure(figsize=(9.0, 2.2 + 1.8 * d), layout="constrained")
    axes = fig.subplots(d, 1, sharex=True, squeeze=False)[:, 0]
    t = trace.t[keep]
    for i, (ax, axis) in enumerate(zip(axes, trace.axes)):
        before = diagnosis.residual_before[:, i]
        before = 1e3 * (before - before[keep].mean())[keep]
        after = 1e3 * diagnosis.residual_after[keep, i]
        drawn = envelope_indices(np.column_stack([before, after]))
        ax.plot(t[drawn], before[drawn], label="before: nominal model (zero offset removed)", **_BEFORE)
        ax.plot(t[drawn], after[drawn], label=_after(diagnosis), **_AFTER)
        for sign in (-1, 1):
            ax.axhline(sign * diagnosis.noise_um[i], color="k", lw=0.7, ls="--", zorder=3,
                       label="noise ±1σ" if sign > 0 else None)
        ax.set_ylabel(f"{axis}: measured − simulated [µm]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    axes[0].set_title("Residual before and after the diagnosis")
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_magnified(diagnosis, ax=None):
    """The trace magnified, before and after the diagnosis.

    With two or more axes: the XY reference path, and the residual
    (measured − simulated) along the path normal drawn magnified on it,
    ``reference + k·(r·n)·n``, for the nominal model (zero offset removed)
    and after the diagnosis. With one axis: the following error
    (reference − position) over time, measured and simulated both ways [µm].
    "Before" is a wide light band under the thin "after" line; the legend
    sits below the axes.

    Parameters
    ----------
    diagnosis : Diagnosis
    ax : matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt

    from .plotting import _drawing_size, _drawn_curve, envelope_indices, magnification_for

    trace, keep = diagnosis.trace, diagnosis.scored
    ax = ax or plt.figure(figsize=(7.0, 7.0), layout="constrained").add_subplot()
    after = _after(diagnosis)
    if len(trace.axes) == 1:
        t = trace.t[keep]
        simulated = (("measured", trace.actual), ("nominal model", diagnosis.simulated_before),
                     (after, diagnosis.simulated_after))
        runs = [(label, 1e3 * (trace.reference - y)[keep, 0]) for label, y in simulated]
        drawn = envelope_indices(np.column_stack([y for _, y in runs]))
        styles = (dict(color="k", lw=0.7), _BEFORE, _AFTER)
        for (label, y), style in zip(runs, styles):
            ax.plot(t[drawn], y[drawn], label=label, **style)
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"{trace.axes[0]}: following error [µm]")
        ax.set_title("Following error, measured and simulated")
    else:
        ref = trace.reference[keep, :2]
        before = diagnosis.residual_before[keep, :2]
        runs = (("before: nominal model", _BEFORE, before - before.mean(axis=0)),
                (after, _AFTER, diagnosis.residual_after[keep, :2]))
        normals = [(label, style, path_normal(ref, r)) for label, style, r in runs]
        size = _drawing_size(ref)  # 1 mm for a reference that stands still (its drawing a point)
        k = magnification_for(size, max(float(np.percentile(np.abs(n), 99)) for *_, n in normals))
        tangent = np.gradient(ref, axis=0)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
        unit = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        step = size / 1200  # cells of the drawing: about its pixels
        ax.plot(*_drawn_curve(ref, step).T, color="0.6", lw=0.8, label="reference")
        for label, style, normal in normals:
            ax.plot(*_drawn_curve(ref + k * normal[:, None] * unit, step).T, label=label, **style)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{trace.axes[0]} [mm]")
        ax.set_ylabel(f"{trace.axes[1]} [mm]")
        ax.set_title(f"Residual (measured − simulated) along the path normal, magnified ×{k:g}")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, frameon=False)
    return ax


def plot_polar(diagnosis, ax=None):
    """Polar plot of a circle test: the radial residual (measured − simulated) before and after the diagnosis [µm].

    Drawn against the reference's angle over the samples whose reference
    has been on the test circle for five time constants of the slowest
    closed-loop pole (not on a run-in arc): the shape a ballbar
    technician reads, of what the nominal model misses and of what is left.
    The rings follow the data (:func:`contoursim.plotting.plot_polar_deviation`
    does the same), their labels on a white ground where the data keeps off
    them; zero is the dashed circle, drawn over the data. "Before" is a
    wide light band under the thin "after" line; the legend sits below.

    Parameters
    ----------
    diagnosis : Diagnosis
    ax : matplotlib.axes.Axes with polar projection, optional

    Returns
    -------
    matplotlib.axes.Axes or None
        ``None`` when the trace is not a circle test.
    """
    import matplotlib.pyplot as plt

    from .plotting import _polar_frame, envelope_indices

    trace, keep = diagnosis.trace, diagnosis.scored
    circle = _circle(trace.reference[keep])
    if circle is None:
        return None
    center, radius = circle
    rel = trace.reference[keep, :2] - center[:2]
    r = np.linalg.norm(rel, axis=1)
    on = np.abs(r - radius) < 1e-3 * radius
    lag = int(np.ceil(5.0 * max(_settling_time(diagnosis.model.machine.axes[a]) for a in trace.axes) / trace.dt))
    on[lag:] &= np.convolve(~on, np.ones(lag + 1), mode="full")[: on.size][lag:] == 0
    on[:lag] = False
    if not on.any():
        return None
    ax = ax or plt.figure(figsize=(6.4, 7.4), layout="constrained").add_subplot(projection="polar")
    theta = np.arctan2(rel[on, 1], rel[on, 0])
    unit = rel[on] / r[on, None]
    before = diagnosis.residual_before[keep][on, :2]
    before = before - before.mean(axis=0)  # the instrument's zero, as the refit removes it
    devs = [1e3 * np.sum(d * unit, axis=1) for d in (before, diagnosis.residual_after[keep][on, :2])]
    drawn = envelope_indices(np.column_stack(devs))
    _polar_frame(ax, [(theta[drawn], dev[drawn]) for dev in devs])
    for label, style, dev in zip(("before: nominal model", _after(diagnosis)), (_BEFORE, _AFTER), devs):
        ax.plot(theta[drawn], dev[drawn], label=label, **style)
    ax.set_title(f"Circle R = {radius:.4g} mm: radial residual, measured − simulated [µm]", fontsize="medium")
    ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.06), frameon=False)
    return ax


#: The files :func:`save_figures` writes (the polar plot for a circle test only).
FIGURE_FILES = ("diagnosis_residual.png", "diagnosis_trace.png", "diagnosis_polar.png")


def save_figures(diagnosis, out):
    """Write the diagnosis figures as PNG files into the output folder `out` (:data:`FIGURE_FILES`).

    ``diagnosis_residual.png`` (:func:`plot_residuals`),
    ``diagnosis_trace.png`` (:func:`plot_magnified`) and, for a circle
    test, ``diagnosis_polar.png`` (:func:`plot_polar`).

    Parameters
    ----------
    diagnosis : Diagnosis
    out : str, Path or contoursim.output.OutputDir
        Created if missing; a file there that contoursim did not write is never replaced.

    Returns
    -------
    list of pathlib.Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .output import output_dir

    out = output_dir(out)
    residual, trace, polar = FIGURE_FILES
    figures = [(residual, plot_residuals(diagnosis)), (trace, plot_magnified(diagnosis).figure)]
    drawn = plot_polar(diagnosis)
    if drawn is not None:
        figures.append((polar, drawn.figure))
    try:
        files = [out.file(name) for name, _ in figures]  # all refused before any is written
        for name, fig in figures:
            with out.write(name, binary=True) as stream:
                fig.savefig(stream, format="png", dpi=110)
    finally:
        for _, fig in figures:
            plt.close(fig)
    return files
