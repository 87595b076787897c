"""Compensation strategies: feedforward, ZPETC, cross-coupled contour control, and their compositions.

A strategy is an object passed to :func:`contoursim.simulation.simulate`
(``strategies=[...]``). It acts at one or more stages of the data flow, each
a method of :class:`Strategy` that leaves things unchanged by default:

============  ==========================================  ==========================================
stage         method                                      strategies
============  ==========================================  ==========================================
target        ``target(q, v, a, t)``: where the axes       :class:`~contoursim.geocomp.GeometricCompensation`
              should go
drive         ``drive(servos)``: the drives' settings      :class:`Feedforward` (velocity and
                                                          acceleration feedforward gains)
pre-filter    ``prefilter(q, v, a, servos, dt)``: the      :class:`ZPETC`
              commands sent, not the target
in the loop   ``coupling(path, servos, dt)``: a            :class:`CrossCoupled`
              :class:`contoursim.kernel.Coupling`
============  ==========================================  ==========================================

Strategies compose (:class:`Composition`): any number of target stages,
applied in order; at most one feedforward (:class:`Feedforward` or
:class:`ZPETC`: two inverses of one loop would each undo what the other
did); at most one cross-coupled controller.

Feedforward is one mechanism: the drive's own velocity and acceleration
feedforward paths (:class:`contoursim.servo.AxisServo` ``vff``/``aff``,
stepped by the kernel). A machine file's ``vff``/``aff`` say how the drives
are set up (the ``none`` strategy keeps them); :class:`Feedforward` sets
them for a comparison, and :class:`ZPETC` switches them off because its
pre-filter replaces them.

A strategy designs from a *model* of the axes (``model``: axis name ->
AxisServo); by default the simulated machine's own servos (a perfect
model). Passing the nominal servos while simulating another machine gives
the model mismatch a real controller lives with.
"""

import abc
import dataclasses
from collections.abc import Mapping
from functools import lru_cache
from types import MappingProxyType

import numpy as np

from . import _validate, kernel
from .estimators import search_params
from .exceptions import UnstableLoopError
from .coupled_loop import (
    DESIGN_DAMPING_RATIO,
    coupled_margins,
    coupled_spectral_radius,
    designed_gains,
    margins_along,
    path_frames,
)
from .servo import MIN_DAMPING_RATIO, MIN_PHASE_MARGIN_DEG, AxisServo

__all__ = [
    "Strategy",
    "Feedforward",
    "ZPETC",
    "zpetc_commands",
    "CrossCoupled",
    "Composition",
    "strategy_sequence",
    "STRATEGY_NAMES",
    "strategies_named",
    "coupled_spectral_radius",
    "coupled_margins",
    "path_frames",
    "designed_gains",
    "DESIGN_DAMPING_RATIO",
    "STRATEGY_KEYS",
    "strategy_setting",
]

#: The comparison's strategy names (DESIGN.md contract), in the order ``contoursim compare`` runs them.
STRATEGY_NAMES = ("none", "feedforward", "zpetc", "ccc_linear", "ccc_arc", "feedforward+ccc_arc")


class Strategy(abc.ABC):
    """What a compensation strategy may change; every stage leaves things unchanged unless overridden.

    A subclass says what it is (``name``, ``kind``) and overrides the
    stages where it acts.
    """

    @property
    @abc.abstractmethod
    def name(self):
        """Its name in a comparison (as in :data:`STRATEGY_NAMES`)."""

    @property
    @abc.abstractmethod
    def kind(self):
        """``"target"``, ``"feedforward"`` or ``"coupling"``: the composition rule of :class:`Composition`."""

    def target(self, q, v, a, t):
        """Where the axes should go: axis positions [mm, rad], velocities, accelerations, each (N, n_axes)."""
        return q, v, a

    def drive(self, servos):
        """The drives' settings: mapping axis name -> AxisServo, returned changed or as is."""
        return servos

    def prefilter(self, q, v, a, servos, dt):
        """The commands sent to the servo axes (N, n_servo) for the target `q, v, a` (N, n_servo)."""
        return q, v, a

    def coupling(self, path, servos, dt):
        """A :class:`contoursim.kernel.Coupling` acting in the loop, or ``None``."""
        return None

    def preview(self, servos, dt):
        """Samples the pre-filter reads ahead of the one it sends: the machine dwells this long at the start [-]."""
        return 0

    def settings(self, servos, dt):
        """Its settings on `servos` at period `dt` [s] by their ``[[strategy]]`` keys (:data:`STRATEGY_KEYS`), and what follows."""
        return {}


def _model(model, servos):
    """The servos a strategy designs from: `model` (for the axes it names) or the simulated ones."""
    if model is None:
        return dict(servos)
    missing = [axis for axis in servos if axis not in model]
    if missing:
        raise ValueError(f"the strategy's model has no servo for axis {missing[0]!r}")
    return {axis: model[axis] for axis in servos}


def _check_model(model):
    if model is None:
        return None
    if not isinstance(model, Mapping):
        raise TypeError(f"model must be a mapping axis name -> AxisServo, got {type(model).__name__}")
    for axis, servo in model.items():
        if not isinstance(servo, AxisServo):
            raise TypeError(f"model[{axis!r}] must be an AxisServo, got {type(servo).__name__}")
    return dict(model)


# ---------------------------------------------------------------------------------------------
# Feedforward


@dataclasses.dataclass(frozen=True, eq=False)
class Feedforward(Strategy):
    """Velocity and acceleration feedforward: the drives' own ``vff``/``aff`` paths, switched on.

    The position controller's velocity command gets ``velocity · v_ref`` and
    the current command ``acceleration · m·a_ref/kf`` (mass and force
    constant of the model), so that an exact model leaves only the sampling
    and the velocity loop's own lag to the feedback.

    Parameters
    ----------
    velocity : float, default 1
        Velocity feedforward gain [-], 0..1.
    acceleration : float, default 1
        Acceleration feedforward gain [-], 0..1, on the model's ``m/kf``.
    model : mapping str -> AxisServo, optional
        Servos the acceleration feedforward is computed from (default: the
        simulated machine's). The drive gets ``aff = acceleration ·
        (m/kf)_model / (m/kf)_machine``, which must not exceed 1.
    """

    velocity: float = 1.0
    acceleration: float = 1.0
    model: Mapping | None = None

    name = "feedforward"
    kind = "feedforward"

    def __post_init__(self):
        for gain in ("velocity", "acceleration"):
            value = _validate.nonnegative(gain, getattr(self, gain))
            if value > 1:
                raise ValueError(f"{gain} must be between 0 and 1 (a fraction of full feedforward), got {value!r}")
            object.__setattr__(self, gain, value)
        object.__setattr__(self, "model", _check_model(self.model))

    def settings(self, servos, dt):
        return {"velocity_fraction": self.velocity, "acceleration_fraction": self.acceleration}

    def drive(self, servos):
        model = _model(self.model, servos)
        driven = {}
        for axis, servo in servos.items():
            ratio = (model[axis].mass / model[axis].force_constant) / (servo.mass / servo.force_constant)
            aff = self.acceleration * ratio
            if aff > 1 + 1e-12:
                raise ValueError(
                    f"the feedforward model of axis {axis!r} has {100 * (ratio - 1):.3g} % more mass per force "
                    f"constant than the machine: acceleration feedforward would be {aff:.4g} > 1"
                )
            driven[axis] = dataclasses.replace(servo, vff=self.velocity, aff=min(aff, 1.0))
        return driven


# ---------------------------------------------------------------------------------------------
# ZPETC

#: A closed-loop zero with ``|z|`` at least this is not inverted by ZPETC (besides any on the negative
#: real half-plane with ``|z| > ZPETC_NEGATIVE_RADIUS``).
ZPETC_RADIUS = 1.0
#: Zeros on the left half of the z-plane beyond this radius ring at the Nyquist frequency when inverted.
ZPETC_NEGATIVE_RADIUS = 0.5


@lru_cache(maxsize=64)
def _zpetc_filter(servo, dt, negative_radius=ZPETC_NEGATIVE_RADIUS):
    """``(den, num, fir, delay)`` of Tomizuka's ZPETC for the sampled loop x_ref -> x of `servo`.

    The sampled closed loop (:func:`contoursim.servo.discretize`, feedforward
    off) is ``G(z) = z^-d · k·B_a(z^-1)·B_u(z^-1) / A(z^-1)``, with ``B_a``
    the zeros that may be cancelled and ``B_u`` those that may not. The
    pre-filter is

        F(z) = z^d · A(z^-1) · B_u(z) / (k · B_a(z^-1) · B_u(1)^2),

    so that ``G·F = B_u(z^-1)·B_u(z) / B_u(1)^2``: zero phase at every
    frequency and unit gain at DC. Returned as the causal IIR part
    ``A/(k·B_a)`` (``num``/``den`` in powers of z^-1), the non-causal FIR
    ``B_u(z)/B_u(1)^2`` (coefficients of z^0, z^1, ...) and the advance d.
    """
    import scipy.linalg

    loop = dataclasses.replace(servo, vff=0.0, aff=0.0).discretize(dt).closed_loop
    A, B, C, D = loop.A, loop.B[:, [0]], loop.C[[0]], loop.D[[0]][:, [0]]
    poles = np.linalg.eigvals(A)
    n = A.shape[0]
    pencil = np.block([[A, B], [C, D]])
    singular = np.zeros_like(pencil)
    singular[:n, :n] = np.eye(n)
    with np.errstate(all="ignore"):
        zeros = scipy.linalg.eigvals(pencil, singular)
    zeros = zeros[np.isfinite(zeros) & (np.abs(zeros) < 1e8)]
    delay = n - zeros.size
    unacceptable = (np.abs(zeros) >= ZPETC_RADIUS) | ((zeros.real < 0) & (np.abs(zeros) > negative_radius))
    dc = (C @ np.linalg.solve(np.eye(n) - A, B) + D).item()
    # np.poly of no roots is the scalar 1.0: a loop without zeros (a P velocity loop) has polynomials of degree 0
    a_poly, ba_poly, bu_poly = (np.atleast_1d(np.poly(r)).real for r in (poles, zeros[~unacceptable], zeros[unacceptable]))
    # G(1) = k·B_a(1)·B_u(1)/A(1) fixes the gain k
    k = dc * a_poly.sum() / (ba_poly.sum() * bu_poly.sum())
    return ba_poly * k, a_poly, bu_poly / bu_poly.sum() ** 2, delay


def _negative_radius(value):
    """`value` after checking it is a radius in the z-plane, 0..1 (ZPETC's `negative_radius`)."""
    radius = _validate.nonnegative("negative_radius", value)
    if radius > 1:
        raise ValueError(f"negative_radius must be between 0 and 1 (a radius in the z-plane), got {radius!r}")
    return radius


def zpetc_commands(servo, dt, q, negative_radius=ZPETC_NEGATIVE_RADIUS):
    """ZPETC pre-filtered position commands for one axis (see :class:`ZPETC`).

    Parameters
    ----------
    servo : AxisServo
        The model of the axis (its feedforward gains are ignored).
    dt : float
        Servo period [s].
    q : ndarray, shape (N,)
        Target positions [mm], at rest before the first sample and after the last.
    negative_radius : float
        Zeros on the left half-plane beyond this radius are compensated in phase only (see :class:`ZPETC`).

    Returns
    -------
    ndarray, shape (N,)
        Commands [mm] the sampled loop turns into `q` with zero phase error.
    """
    from scipy.signal import lfilter

    if not isinstance(servo, AxisServo):
        raise TypeError(f"servo must be an AxisServo, got {type(servo).__name__}")
    dt = _validate.positive("dt", dt)
    q = _validate.finite_array("q", q, ndim=1)
    if q.size == 0:
        raise ValueError("q must hold at least one target position, got none")
    den, num, fir, delay = _zpetc_filter(servo, dt, _negative_radius(negative_radius))
    start, end = q[0], q[-1]
    ahead = fir.size - 1 + delay
    held = np.concatenate([q - start, np.full(ahead, end - start)])
    causal = lfilter(num, den, held)
    # non-causal FIR over the future samples, then the advance by the loop's delay
    shifted = sum(c * causal[j : j + q.size + delay] for j, c in enumerate(fir))
    return start + shifted[delay : delay + q.size]


@dataclasses.dataclass(frozen=True, eq=False)
class ZPETC(Strategy):
    """Tomizuka's zero-phase-error tracking controller: the sampled closed loop's inverse, before the loop.

    Each servo axis's command is pre-filtered by the stable part of the
    inverse of its sampled closed loop ``x_ref -> x`` (exactly the loop the
    kernel steps: ZOH plant, sampled PI controllers), with the zeros that cannot
    be inverted (outside or on the unit circle, or near -1 where the ZOH puts
    its sampling zeros: they would ring at the Nyquist frequency) compensated
    in phase only; the filter looks ahead a few servo periods (the loop's
    delay and the non-invertible zeros, :meth:`preview`), as the
    interpolator's look-ahead allows: :func:`contoursim.simulation.simulate`
    has the machine dwell that long at the start point while the filter
    fills, so that the first command sent is the start point. The drives'
    own velocity and acceleration feedforward is switched off: the
    pre-filter takes its place. The velocity and acceleration
    commands become the central differences of the filtered position.

    Parameters
    ----------
    model : mapping str -> AxisServo, optional
        Servos the inverse is built from (default: the simulated machine's).
    negative_radius : float, default 0.5
        Zeros of the sampled loop on the left half of the z-plane beyond
        this radius (the ZOH's sampling zeros) are compensated in phase
        only, not inverted [-], 0..1: lower inverts fewer of them and
        previews further ahead.

    References
    ----------
    M. Tomizuka, "Zero phase error tracking algorithm for digital control",
    ASME J. Dyn. Syst. Meas. Control 109 (1987) 65-68.
    """

    model: Mapping | None = None
    negative_radius: float = ZPETC_NEGATIVE_RADIUS

    name = "zpetc"
    kind = "feedforward"

    def __post_init__(self):
        object.__setattr__(self, "model", _check_model(self.model))
        object.__setattr__(self, "negative_radius", _negative_radius(self.negative_radius))

    def settings(self, servos, dt):
        return {"negative_zero_radius": self.negative_radius, "preview_samples": self.preview(servos, dt)}

    def drive(self, servos):
        return {axis: dataclasses.replace(servo, vff=0.0, aff=0.0) for axis, servo in servos.items()}

    def preview(self, servos, dt):
        model = _model(self.model, servos)
        filters = (_zpetc_filter(model[axis], float(dt), self.negative_radius) for axis in servos)
        return max(fir.size - 1 + delay for _, _, fir, delay in filters)

    def prefilter(self, q, v, a, servos, dt):
        model = _model(self.model, servos)
        q = np.column_stack([zpetc_commands(model[axis], dt, q[:, i], self.negative_radius)
                             for i, axis in enumerate(servos)])
        v = np.gradient(q, dt, axis=0)
        return q, v, np.gradient(v, dt, axis=0)


# ---------------------------------------------------------------------------------------------
# Cross-coupled control


#: Largest coupling gains of :class:`CrossCoupled`: kp [1/s], ki [1/s^2], kd [-]. Far beyond any gain a sampled loop
#: takes (the loop check refuses them); beyond, the default ki, ``(Kp + kp)^2 / 4``, overflows.
MAX_COUPLING_GAIN = MappingProxyType({"kp": 1e9, "ki": 1e18, "kd": 1e9})


@dataclasses.dataclass(frozen=True, eq=False)
class CrossCoupled(Strategy):
    """Koren's cross-coupled contour controller, every servo period inside the loop.

    The contour error of the fed-back position of the first 2 or 3 servo
    axes is estimated every period (``"linear"``: the tangent at the
    commanded sample, Koren's variable gains ``Cx = -sin θ``, ``Cy = cos θ``;
    ``"arc"``: the three-point circumscribed arc with its out-of-plane part,
    seed 003) and a PID of it is added to the velocity commands along the
    path normal (:class:`contoursim.kernel.Coupling`).

    Parameters
    ----------
    estimator : {"arc", "linear"}, default "arc"
    kp : float, optional
        Coupling gain [1/s]. Default: designed on the model's sampled loops
        so that the coupled loop's least damped pole has ζ = 0.7 on every
        straight line (:func:`designed_gains`).
    ki : float, optional
        Integral gain [1/s^2]. Default ``K^2 / 4`` with ``K = Kp + kp``
        (``Kp`` the smallest position gain of the coupled axes): the PI
        corner a quarter of the contour loop's gain, which removes the
        steady contour error on a line or an arc.
    kd : float, default 0
        Derivative gain [-].
    model : mapping str -> AxisServo, optional
        Servos the default gains are derived from (default: the simulated
        machine's).
    up : array_like, shape (3,), default (0, 0, 1)
        Orients the local plane normal.
    window : int, default 4
        Samples the arc estimator's search descends over either side of the
        previous foot before it scans (:func:`contoursim.nearest.nearest_knot`):
        speed only, the estimate does not depend on it.

    Notes
    -----
    Before a run, :meth:`coupling` checks the coupled loop as
    :func:`contoursim.servo.check` checks an axis loop: the simulated axes'
    sampled loops (without their in-loop effects) with the coupling closed,
    linearised across every direction the path's normal takes
    (:func:`path_frames`, :meth:`margins`), must be stable with a phase
    margin of at least 30° and a closed-loop damping ratio of at least 0.2;
    otherwise :class:`~contoursim.exceptions.UnstableLoopError` names the
    gains and the margins. The linearisation is frozen in time (the
    normal's turning rate is not in it); what it cannot see (saturation,
    friction) the kernel's divergence detection reports.
    """

    estimator: str = "arc"
    kp: float | None = None
    ki: float | None = None
    kd: float = 0.0
    model: Mapping | None = None
    up: tuple = (0.0, 0.0, 1.0)
    window: int = 4

    kind = "coupling"

    def __post_init__(self):
        if self.estimator not in kernel.COUPLING_ESTIMATORS:
            raise ValueError(f"estimator must be one of {', '.join(kernel.COUPLING_ESTIMATORS)}, got {self.estimator!r}")
        for gain in ("kp", "ki", "kd"):  # kp = 1e300 overflowed the default ki, (Kp + kp)^2 / 4, in a traceback
            if getattr(self, gain) is not None:
                value = _validate.nonnegative(gain, getattr(self, gain))
                if value > MAX_COUPLING_GAIN[gain]:
                    raise ValueError(f"{gain} must be at most {MAX_COUPLING_GAIN[gain]:g}, got {value:g}")
                object.__setattr__(self, gain, value)
        object.__setattr__(self, "model", _check_model(self.model))
        if isinstance(self.window, bool) or not isinstance(self.window, (int, np.integer)) or self.window < 1:
            raise ValueError(f"window must be a whole number of samples, at least 1; got {self.window!r}")
        object.__setattr__(self, "up", tuple(search_params(self.up)[:3].tolist()))  # (0, 0, 0) failed in the run

    @property
    def name(self):
        return f"ccc_{self.estimator}"

    @property
    def gains_origin(self):
        """How its gains were chosen: ``"set"``, ``"designed"`` (:func:`designed_gains`) or
        ``"kp_per_s set, ki_per_s2 designed"`` (by the keys of :meth:`settings`)."""
        if self.kp is not None and self.ki is not None:
            return "set"
        return "designed" if self.kp is None else "kp_per_s set, ki_per_s2 designed"

    def settings(self, servos, dt):
        kp, ki, kd = self.gains(self._coupled(servos), dt)
        return {"kp_per_s": kp, "ki_per_s2": ki, "kd": kd}

    def _coupled(self, servos):
        """The first 2 or 3 of `servos`: the axes it couples (on one axis its design failed in numpy's matmul)."""
        coupled = dict(list(servos.items())[:3])
        if len(coupled) < 2:
            raise ValueError(f"{self.name}: cross-coupled control needs 2 or 3 servo axes, the machine has "
                             f"{len(servos)} ({', '.join(servos)})")
        return coupled

    def gains(self, servos, dt):
        """``(kp, ki, kd)`` of the coupling for the coupled `servos` (mapping axis -> AxisServo) at period `dt` [s].

        Gains not set are designed in discrete time on the model's sampled
        loops (:func:`designed_gains`).
        """
        if self.kp is not None and self.ki is not None:
            return self.kp, self.ki, self.kd
        kp, ki = designed_gains(_model(self.model, servos), dt, self.kd, self.kp)
        return kp, ki if self.ki is None else self.ki, self.kd

    def margins(self, path, servos, dt):
        """The coupled loop's margins along `path`, the worst of each over the path's frames (see :func:`path_frames`).

        Parameters
        ----------
        path : ndarray, shape (N, n)
            The coupled axes' target path [mm].
        servos : mapping str -> AxisServo
            The coupled axes as simulated (their loops, not the model's).
        dt : float
            Servo period [s].

        Returns
        -------
        dict
            ``kp``, ``ki``, ``kd``, then :func:`~contoursim.coupled_loop.margins_along`'s.
        """
        kp, ki, kd = self.gains(servos, dt)
        # the loop without feedforward, which does not enter it: one analysis for a strategy with and without
        rows = [kernel.pack(dataclasses.replace(servo, vff=0.0, aff=0.0), dt) for servo in servos.values()]
        return dict(kp=kp, ki=ki, kd=kd, **margins_along(rows, kp, ki, kd, dt, path, self.up))

    def coupling(self, path, servos, dt):
        coupled = self._coupled(servos)
        path = path[:, : len(coupled)]
        m = self.margins(path, coupled, dt)  # the loops as simulated, not as modelled
        if m["spectral_radius"] >= 1.0:
            problem = f"is unstable (spectral radius {m['spectral_radius']:.6g} >= 1)"
        elif m["phase_margin"] < MIN_PHASE_MARGIN_DEG or m["damping_ratio"] < MIN_DAMPING_RATIO:
            problem = (f"is badly damped (needs phase margin >= {MIN_PHASE_MARGIN_DEG:g} deg and "
                       f"closed-loop damping ratio >= {MIN_DAMPING_RATIO:g}, as an axis loop)")
        else:
            return kernel.Coupling(self.estimator, path, m["kp"], m["ki"], m["kd"], self.up, self.window)
        raise UnstableLoopError(
            f"cross-coupled control with kp = {m['kp']:g} 1/s, ki = {m['ki']:g} 1/s^2, kd = {m['kd']:g}: the coupled "
            f"loop of axes {', '.join(coupled)} {problem} on this path: phase margin {m['phase_margin']:.3g} deg "
            f"(at reference sample {m['sample']}), damping ratio {m['damping_ratio']:.3g}, gain margin "
            f"{m['gain_margin']:.3g}, over the {m['frames']} directions of its normal; lower the coupling gains",
            margins=m,
        )


# ---------------------------------------------------------------------------------------------
# Composition


def strategy_sequence(strategies):
    """`strategies` as a tuple, after checking it is a sequence, not one strategy alone or a strategy's name.

    Parameters
    ----------
    strategies : sequence of Strategy
        As :func:`contoursim.simulation.simulate` and :class:`Composition` take them.

    Raises
    ------
    TypeError
        `strategies` is a :class:`Strategy`, a string or not iterable.
    """
    if isinstance(strategies, (Strategy, str)) or not hasattr(strategies, "__iter__"):
        raise TypeError(f"strategies must be a sequence of compensation Strategy objects, e.g. (Feedforward(),), "
                        f"or strategies_named('ccc_arc'); got {strategies!r}")
    return tuple(strategies)


class Composition:
    """Several strategies acting together, each stage in the order given (see the module docstring).

    Parameters
    ----------
    strategies : sequence of Strategy
        At most one feedforward (:class:`Feedforward`, :class:`ZPETC`) and
        one cross-coupled controller; any number of target stages.

    Raises
    ------
    TypeError
        An element is not a :class:`Strategy`.
    ValueError
        Two feedforwards or two cross-coupled controllers.
    """

    def __init__(self, strategies=()):
        strategies = strategy_sequence(strategies)
        for i, strategy in enumerate(strategies):
            if not isinstance(strategy, Strategy):
                raise TypeError(f"strategies[{i}] must be a compensation Strategy, got {type(strategy).__name__}")
        for kind in ("feedforward", "coupling"):
            same = [s.name for s in strategies if s.kind == kind]
            if len(same) > 1:
                raise ValueError(f"strategies {' and '.join(same)} are both a {kind}: choose one")
        self.strategies = strategies

    @property
    def prefilters(self):
        """Whether a strategy pre-filters the commands (see :meth:`Strategy.prefilter`)."""
        return any(type(s).prefilter is not Strategy.prefilter for s in self.strategies)

    @property
    def name(self):
        """``"+"``-joined strategy names, ``"none"`` for none."""
        return "+".join(s.name for s in self.strategies) or "none"

    def target(self, q, v, a, t):
        """Every target stage in turn (see :meth:`Strategy.target`)."""
        for strategy in self.strategies:
            q, v, a = strategy.target(q, v, a, t)
        return q, v, a

    def drive(self, servos):
        """Every drive stage in turn (see :meth:`Strategy.drive`)."""
        servos = dict(servos)
        for strategy in self.strategies:
            servos = strategy.drive(servos)
        return servos

    def preview(self, servos, dt):
        """Samples the pre-filters read ahead, together (see :meth:`Strategy.preview`)."""
        return sum(strategy.preview(servos, dt) for strategy in self.strategies)

    def prefilter(self, q, v, a, servos, dt):
        """Every pre-filter stage in turn (see :meth:`Strategy.prefilter`)."""
        for strategy in self.strategies:
            q, v, a = strategy.prefilter(q, v, a, servos, dt)
        return q, v, a

    def coupling(self, path, servos, dt):
        """The cross-coupled controller's :class:`~contoursim.kernel.Coupling`, or ``None`` (see :meth:`Strategy.coupling`)."""
        for strategy in self.strategies:
            coupling = strategy.coupling(path, servos, dt)
            if coupling is not None:
                return coupling
        return None


#: ``[[strategy]]`` file keys (and ``--set NAME.KEY=VALUE``) of each strategy -> its parameter, in the key's unit.
STRATEGY_KEYS = MappingProxyType({
    "feedforward": MappingProxyType({"velocity_fraction": "velocity", "acceleration_fraction": "acceleration"}),
    "zpetc": MappingProxyType({"negative_zero_radius": "negative_radius"}),
    "ccc_linear": MappingProxyType({"kp_per_s": "kp", "ki_per_s2": "ki", "kd": "kd"}),
    "ccc_arc": MappingProxyType({"kp_per_s": "kp", "ki_per_s2": "ki", "kd": "kd"}),
})


def strategy_setting(name, key, value):
    """A strategy's setting by its file key (:data:`STRATEGY_KEYS`), checked as the strategy checks it.

    Parameters
    ----------
    name : str
        Strategy name (``feedforward``, ``zpetc``, ``ccc_linear``, ``ccc_arc``).
    key : str
        File key, e.g. ``kp_per_s``.
    value : float or int

    Returns
    -------
    float or int
        `value`.

    Raises
    ------
    ValueError
        An unknown name or key (listing the known ones), or a value the strategy refuses.
    """
    if name not in STRATEGY_KEYS:
        raise ValueError(f"no settings for strategy {name!r}: strategies with settings are {', '.join(STRATEGY_KEYS)}")
    strategies_named(name, settings={name: {key: value}})  # the strategy checks it
    return value


def _arguments(part, values):
    """The keyword arguments of strategy `part` from its settings by file key (:data:`STRATEGY_KEYS`), checked."""
    keys = STRATEGY_KEYS[part]
    if not isinstance(values, Mapping):
        raise TypeError(f"the settings of {part} must map its keys ({', '.join(keys)}) to values, got {values!r}")
    for key, value in values.items():
        if key not in keys:
            raise ValueError(f"unknown setting {key!r} of {part}{_validate.closest(key, keys)}; expected one of "
                             f"{', '.join(keys)}")
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"{key} must be a number, got {value!r}")
    return {keys[key]: value for key, value in values.items()}


def strategies_named(name, model=None, chain=None, settings=None):
    """The strategies behind a comparison name such as ``"feedforward+ccc_arc"``.

    Parameters
    ----------
    name : str
        ``"+"``-joined parts from ``none``, ``feedforward``, ``zpetc``,
        ``ccc_linear``, ``ccc_arc`` and ``geometric``.
    model : mapping str -> AxisServo, optional
        The servo model the strategies design from (default: the simulated machine's).
    chain : MachineChain, optional
        The geometric error model, needed by ``geometric``.
    settings : mapping str -> mapping, optional
        The settings of each part by its name, by the keys of a job file's ``[[strategy]]`` table and of
        :meth:`Strategy.settings` (:data:`STRATEGY_KEYS`, e.g. ``{"ccc_arc": {"kp_per_s": 120.0}}``); parts not
        named keep their defaults.

    Returns
    -------
    tuple of Strategy

    Raises
    ------
    ValueError
        An unknown strategy, or settings of one that has none; an unknown key (listing the known ones) or a
        value the strategy refuses (naming the key).
    """
    from .geocomp import GeometricCompensation

    if not isinstance(name, str):
        raise TypeError(f"a strategy name is text such as 'ccc_arc' or 'feedforward+ccc_arc', got {name!r}")
    settings = {} if settings is None else settings
    if not isinstance(settings, Mapping):
        raise TypeError(f"settings must map strategy names to their settings, got {type(settings).__name__}")
    for part in settings:
        if part not in STRATEGY_KEYS:
            raise ValueError(f"no settings for strategy {part!r}: strategies with settings are {', '.join(STRATEGY_KEYS)}")
    arguments = {part: _arguments(part, values) for part, values in settings.items()}
    makers = {
        "none": lambda: None,
        "feedforward": lambda: Feedforward(model=model, **arguments.get("feedforward", {})),
        "zpetc": lambda: ZPETC(model=model, **arguments.get("zpetc", {})),
        "ccc_linear": lambda: CrossCoupled("linear", model=model, **arguments.get("ccc_linear", {})),
        "ccc_arc": lambda: CrossCoupled("arc", model=model, **arguments.get("ccc_arc", {})),
        "geometric": lambda: None if chain is None else GeometricCompensation(chain),
    }
    strategies = []
    parts = name.split("+")
    for i, part in enumerate(parts):
        if part not in makers:
            raise ValueError(f"unknown strategy {part!r} in {name!r}{_validate.closest(part, makers)}: use "
                             f"{', '.join(makers)}, joined by '+'")
        if part in parts[:i]:  # "none+none" ran as a strategy of its own; a strategy twice is refused below
            raise ValueError(f"strategy {part!r} is named twice in {name!r}: name each part once")
        try:
            made = makers[part]()
        except ValueError as exc:  # a value the strategy refuses: said by its file key ("kp_per_s must be ...")
            keys = {parameter: key for key, parameter in STRATEGY_KEYS.get(part, {}).items()}
            parameter = next((p for p in keys if str(exc).startswith(p)), None)
            if parameter is None:
                raise
            raise ValueError(keys[parameter] + str(exc)[len(parameter) :]) from None
        if part == "geometric" and made is None:
            raise ValueError("the geometric strategy needs a machine with a geometric error model (bodies)")
        if made is not None:
            strategies.append(made)
    if "none" in parts and len(parts) > 1:  # ran labelled "none+feedforward", the feedforward alone
        raise ValueError(f"'none' in {name!r}: none is no compensation, not a part of one; name the other parts")
    Composition(strategies)  # checks the combination
    return tuple(strategies)
