"""Multibody chain of a machine tool with its geometric errors.

A machine is a tree of bodies hanging from the bed (body 0): a tool branch
ending at the tool and a workpiece branch ending at the workpiece (seeds 000,
002, 004). The **lower-body array** L^n(j) (L^0(j) = j, L^1(j) = parent(j),
L^n = L(L^(n-1)), L(0) = 0) gives both chains.

Between body j and its parent the actual transform is the product of the
characteristic matrices (seed 000 eq. 1.41, seed 004 eq. 6 and 15)::

    T_j = S_j · ΔS_j · M_j(q) · D_j(t) · E_j(q)

- ``S``: ideal static matrix, a translation by the body's offset [mm];
- ``ΔS``: static (assembly) error, six constants;
- ``M``: ideal motion, a translation ``q·u`` along the joint direction, or for
  a rotary joint a rotation by q about its axis line. With a squareness
  (tilt) error the rotary axis line is the tilted unit vector ``l`` of seed
  001 (l_a, l_b, l_c) and M is the Rodrigues rotation about ``l``;
- ``D``: thermal drift, its own matrix (seed 004 eq. 6, δxt(q), δyt(q),
  δzt(q)): the twist ``τ(t)·(rate + growth·(q − q_ref))`` with τ(t) = t, or
  τ·(1 − exp(−t/τ)) for a first-order drift with time constant τ; rates
  [mm/s, rad/s], and on a linear joint the thermal growth of the axis
  [mm/s per mm] (the screw or scale expands: the drift grows with the
  distance from q_ref, the axis's fixed end or zero);
- ``E``: motion error, the six error motions ``dx, dy, dz, ex, ey, ez`` of
  the axis as functions of q, plus the linear-axis squareness, which enters
  the translation column as ``−ξ·S`` (seed 004 eq. 9 and 11; ξ the carriage
  coordinate along its own axis).

Small rotations are applied exactly (exponential map), so the full product is
an exact rigid-body transform. The tool tip in workpiece coordinates is
``P_w = T_work⁻¹ · T_tool · P_t`` with ``P_t = 0`` in the tool body's frame and
the tool axis ``V_t`` (seed 004 eq. 24-31).

The first-order linearisation: inserting a small twist (δ, ε) at a frame F of
the tool branch moves the tool tip by ``R_W^T (R_F δ + R_F ε × (p − o_F))``,
with (R_F, o_F) the frame's pose and p the tool tip in bed coordinates; on the
workpiece branch the sign is negative. :meth:`MachineChain.error_jacobian`
builds the sensitivity to every named error parameter from that.

Units inside: mm, rad, s. Axis positions q are (N, n_axes), time first.
"""

import re
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import _chainkernels, _validate
from ._blocks import blocks
from ._numba import njit
from .config import FORMAT_DOC, TEXT_KEYS
from .errormotion import _RAD_PER_URAD, COMPONENTS, ERROR_COLUMNS, ERROR_UNITS, Cyclic, ErrorMotion, read_error_table
from .exceptions import ChainError, ConfigError, ContoursimWarning

__all__ = [
    "Body",
    "MachineChain",
    "lower_body_array",
    "tilted_axis",
    "cartesian_chain",
    "chain_from_toml",
]

_DIRECTIONS = "xyz"
_JOINT = re.compile(r"^\s*(fixed|linear|rotary)(?:\s+([+-]?)([xyz]))?\s*$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
MAX_TRAVEL = 1e6  # [mm or rad]: largest |end| of an axis's travel (a kilometre; a trace holds positions as far)
_LARGEST_NUMBER = 1e12  # largest |number| in a machine file's geometric half (offsets, travels, error terms)
_UNIT_TOLERANCE = 1e-9  # a tool axis is a unit vector: its length within this of 1 [-]
SMALL_ERROR = 0.01  # a machine file's error motions stay within this: [rad] of angle, and of a linear travel's length


def lower_body_array(parents):
    """Lower-body array of a tree of bodies.

    Parameters
    ----------
    parents : sequence of int, length n
        ``parents[j - 1]`` is the parent of body j (1..n); 0 is the bed.

    Returns
    -------
    ndarray of int, shape (K, n)
        Row k holds L^k(j) for bodies j = 1..n; the last row is all zeros
        (K − 1 is the depth of the deepest body), as in seed 004, Table 1.

    Raises
    ------
    ChainError
        A parent out of range, or a body that is its own ancestor: its
        ``body`` is that body (one on the cycle).
    """
    parents = np.asarray(parents)
    if parents.ndim != 1 or parents.size == 0 or not np.issubdtype(parents.dtype, np.integer):
        raise ValueError(f"parents must be a non-empty 1-D sequence of integers, got {parents!r}")
    n = parents.size
    bad = np.flatnonzero((parents < 0) | (parents > n))
    if bad.size:
        j = int(bad[0]) + 1
        raise ChainError(f"parents: body {j} has parent {int(parents[j - 1])}, which is not a body 0..{n}", "parent", j)
    lookup = np.concatenate([[0], parents])  # L(0) = 0
    rows = [np.arange(1, n + 1)]
    while rows[-1].any():
        if len(rows) > n:  # n steps up from any body reach the bed, or a body on a cycle
            j = int(rows[-1][rows[-1] > 0][0])
            raise ChainError(f"parents: body {j} is its own ancestor (the bodies do not form a tree)", "parent", j)
        rows.append(lookup[rows[-1]])
    return np.array(rows)


def tilted_axis(direction, tilt):
    """Unit direction of a rotary axis line tilted by squareness errors (seed 001).

    Parameters
    ----------
    direction : int
        The ideal axis: 0 (A, about x), 1 (B, about y), 2 (C, about z).
    tilt : array_like, shape (3,)
        Squareness angles s_k,d [rad] towards the other two directions d
        (the entry of the own direction is ignored): A uses s_ay, s_az;
        B uses s_bx, s_bz; C uses s_cx, s_cy.

    Returns
    -------
    ndarray, shape (3,)
        ``l_a = [cos s_az cos s_ay, −cos s_az sin s_ay, −sin s_az]``,
        ``l_b = [−sin s_bx, cos s_bx cos s_bz, −cos s_bx sin s_bz]``,
        ``l_c = [−sin s_cx, −cos s_cx sin s_cy, cos s_cx cos s_cy]``.
    """
    sx, sy, sz = _validate.finite_array("tilt", tilt, shape=(3,))
    c, s = np.cos, np.sin
    if direction == 0:
        return np.array([c(sz) * c(sy), -c(sz) * s(sy), -s(sz)])
    if direction == 1:
        return np.array([-s(sx), c(sx) * c(sz), -c(sx) * s(sz)])
    if direction == 2:
        return np.array([-s(sx), -c(sx) * s(sy), c(sx) * c(sy)])
    raise ValueError(f"direction must be 0, 1 or 2, got {direction!r}")


@dataclass(frozen=True, eq=False)
class Body:
    """One body of the machine and the joint to its parent.

    Parameters
    ----------
    name : str
        Unique name (``bed`` is reserved for body 0).
    parent : int
        Index of the parent body (0 = bed).
    joint : str
        ``"fixed"``, ``"linear"`` or ``"rotary"``.
    direction : int
        Joint direction 0, 1, 2 (x, y, z) of a moving joint.
    sign : float
        +1 or −1: the carriage moves along (or about) ``sign·e_direction`` for
        a positive axis command (−1 for a table that carries the workpiece
        opposite to the programmed tool motion).
    axis : str, optional
        Name of the commanded axis driving a moving joint.
    offset : ndarray, shape (3,)
        Ideal static offset from the parent frame [mm].
    static : ndarray, shape (6,)
        Static error (dx, dy, dz [mm], ex, ey, ez [rad]).
    motion : tuple of ErrorMotion, length 6
        Error motions dx, dy, dz [mm], ex, ey, ez [rad] as functions of the
        axis position q [mm or rad].
    squareness : ndarray, shape (3,)
        Linear joint: out-of-squareness S [rad] of the line of motion towards
        each other direction (positive: the angle between the positive axes
        exceeds 90°); enters the motion error as ``δ_d −= ξ·S_d``.
    tilt : ndarray, shape (3,)
        Rotary joint: squareness of the axis line s_k,d [rad] (seed 001).
    thermal : ndarray, shape (6,)
        Thermal drift rates dx, dy, dz [mm/s], ex, ey, ez [rad/s] (at
        ``q = thermal_reference``).
    thermal_growth : ndarray, shape (3,)
        Linear joint: thermal growth dx, dy, dz [mm/s per mm of axis
        position, i.e. 1/s]: the drift rate grows by this much per mm from
        `thermal_reference`, ``rate + growth·(q − thermal_reference)``.
    thermal_reference : float
        Axis position [mm] where the thermal growth is zero (the screw's
        fixed bearing, or the axis zero).
    thermal_time_constant : float
        0 (default): the drift grows linearly in time, ``rate·t``; τ > 0 [s]:
        first order, ``rate·τ·(1 − exp(−t/τ))`` (rate at the start, levels
        off at rate·τ). The same for the growth.
    travel : tuple of float, optional
        Axis travel (min, max) [mm or rad], within ±:data:`MAX_TRAVEL`.
    """

    name: str
    parent: int = 0
    joint: str = "fixed"
    direction: int = 2
    sign: float = 1.0
    axis: str = None
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    static: np.ndarray = field(default_factory=lambda: np.zeros(6))
    motion: tuple = field(default_factory=lambda: (ErrorMotion(),) * 6)
    squareness: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tilt: np.ndarray = field(default_factory=lambda: np.zeros(3))
    thermal: np.ndarray = field(default_factory=lambda: np.zeros(6))
    thermal_growth: np.ndarray = field(default_factory=lambda: np.zeros(3))
    thermal_reference: float = 0.0
    thermal_time_constant: float = 0.0
    travel: tuple = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not _NAME.match(self.name) or self.name == "bed":
            raise ValueError(f"body name must be an identifier other than 'bed', got {self.name!r}")
        if self.joint not in ("fixed", "linear", "rotary"):
            raise ValueError(f"{self.name}: joint must be 'fixed', 'linear' or 'rotary', got {self.joint!r}")
        direction = _validate.positive_int(f"{self.name}.direction", self.direction, least=0)  # True == 1 indexes as a mask
        if direction > 2:
            raise ValueError(f"{self.name}.direction must be 0, 1 or 2 (x, y, z), got {direction}")
        sign = _validate.finite(f"{self.name}.sign", self.sign)
        if sign not in (1, -1):
            raise ValueError(f"{self.name}.sign must be 1 or -1, got {sign:g}")
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "sign", sign)
        if (self.axis is None) != (self.joint == "fixed"):
            raise ValueError(f"{self.name}: a moving joint needs an axis name, a fixed one has none")
        if len(self.motion) != 6 or not all(isinstance(m, ErrorMotion) for m in self.motion):
            raise ValueError(f"{self.name}: motion must be 6 ErrorMotion objects (dx, dy, dz, ex, ey, ez)")
        for name, size in (("offset", 3), ("static", 6), ("squareness", 3), ("tilt", 3), ("thermal", 6), ("thermal_growth", 3)):
            arr = _validate.finite_array(f"{self.name}.{name}", getattr(self, name), shape=(size,))
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if self.squareness[self.direction] or (self.squareness.any() and self.joint != "linear"):
            raise ValueError(f"{self.name}: squareness applies to a linear joint, towards the other two directions")
        if self.tilt[self.direction] or (self.tilt.any() and self.joint != "rotary"):
            raise ValueError(f"{self.name}: tilt applies to a rotary joint, towards the other two directions")
        if self.joint == "fixed" and any(not m.is_zero for m in self.motion):
            raise ValueError(f"{self.name}: a fixed body has no error motions (use static)")
        if self.thermal_growth.any() and self.joint != "linear":
            raise ValueError(f"{self.name}: thermal growth applies to a linear joint (it grows with the axis position)")
        object.__setattr__(self, "thermal_reference", _validate.finite(f"{self.name}.thermal_reference", self.thermal_reference))
        object.__setattr__(self, "thermal_time_constant",
                           _validate.nonnegative(f"{self.name}.thermal_time_constant", self.thermal_time_constant))
        if self.travel is not None:
            lo, hi = _validate.finite_array(f"{self.name}.travel", self.travel, shape=(2,), limit=MAX_TRAVEL)
            if not lo < hi:
                raise ValueError(f"{self.name}.travel must be (min, max) with min < max")
            object.__setattr__(self, "travel", (float(lo), float(hi)))

    def parameters(self):
        """The body's error parameters that are set, as ``{name: value}`` [mm, rad, /s]."""
        out = {}
        for comp, motion in zip(COMPONENTS, self.motion):
            out.update({f"{self.name}.{comp}.{k}": v for k, v in motion.parameters().items()})
        for group, values, comps in (
            ("static", self.static, COMPONENTS),
            ("squareness", self.squareness, _DIRECTIONS),
            ("tilt", self.tilt, _DIRECTIONS),
            ("thermal", self.thermal, COMPONENTS),
            ("thermal_growth", self.thermal_growth, COMPONENTS[:3]),
        ):
            out.update({f"{self.name}.{group}.{c}": float(v) for c, v in zip(comps, values) if v})
        return out

    def scaled(self, factor):
        """A copy with every error multiplied by `factor`."""
        factor = _validate.finite("factor", factor)
        return replace(
            self,
            static=factor * self.static,
            motion=tuple(m.scaled(factor) for m in self.motion),
            squareness=factor * self.squareness,
            tilt=factor * self.tilt,
            thermal=factor * self.thermal,
            thermal_growth=factor * self.thermal_growth,
        )

    def with_parameter(self, key, value):
        """A copy with parameter `key` (the name without the body prefix) set."""
        group, _, rest = key.partition(".")
        if group in COMPONENTS:
            i = COMPONENTS.index(group)
            motion = list(self.motion)
            motion[i] = motion[i].with_parameter(rest, value)
            return replace(self, motion=tuple(motion))
        names = {"static": COMPONENTS, "thermal": COMPONENTS, "thermal_growth": COMPONENTS[:3], "squareness": _DIRECTIONS,
                 "tilt": _DIRECTIONS}
        if group not in names or rest not in names[group]:
            raise ValueError(f"unknown parameter {self.name}.{key}")
        arr = getattr(self, group).copy()
        arr[names[group].index(rest)] = value
        return replace(self, **{group: arr})

    @property
    def has_motion_error(self):
        """True when :meth:`motion_error` is not identically zero."""
        return bool(self.squareness.any()) or not all(m.is_zero for m in self.motion)

    def motion_error(self, q, out=None):
        """Motion error twist (dx, dy, dz, ex, ey, ez) at positions `q`, squareness included.

        Parameters
        ----------
        q : ndarray, shape (N,)
            Axis positions [mm or rad].
        out : ndarray, shape (N, 6), optional
            Where to write the result.

        Returns
        -------
        ndarray, shape (N, 6)
            [mm, rad], in the body's frame after its ideal motion.
        """
        q = np.ascontiguousarray(q, dtype=float)
        out = np.empty((q.size, 6)) if out is None else out
        for i, m in enumerate(self.motion):
            if m.is_zero:
                out[:, i] = 0.0
            else:
                m(q, out=out[:, i])
        for i in np.flatnonzero(self.squareness):
            out[:, i] -= (self.sign * self.squareness[i]) * q
        return out

    @property
    def drifts(self):
        """True when the thermal drift is not identically zero."""
        return bool(self.thermal.any() or self.thermal_growth.any())

    def thermal_drift(self, t, q=None, out=None):
        """Thermal drift twist ``τ(t)·(rate + growth·(q − q_ref))`` (dx, dy, dz, ex, ey, ez).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times [s].
        q : ndarray, shape (N,), optional
            Axis positions [mm]; needed when the body has a thermal growth.
        out : ndarray, shape (N, 6), optional
            Where to write the result.

        Returns
        -------
        ndarray, shape (N, 6)
            [mm, rad], in the body's frame after its ideal motion.
        """
        out = np.empty((np.size(t), 6)) if out is None else out
        tau = self.thermal_time(t)
        for c, rate in enumerate(self.thermal):  # column by column: contiguous in the chain's (6, N) rows
            if c < 3 and self.thermal_growth[c]:
                rate = rate + self.thermal_growth[c] * (q - self.thermal_reference)
            np.multiply(tau, rate, out=out[:, c])
        return out

    def thermal_time(self, t):
        """What the drift rates multiply: ``t``, or ``τ·(1 − exp(−t/τ))`` for a first-order drift [s]."""
        tau = self.thermal_time_constant
        return t if tau == 0 else -tau * np.expm1(-t / tau)

    def tilt_twist(self, q):
        """First-order equivalent of the axis-line tilt: a twist after the ideal rotation, shape (N, 6).

        With ``Q = I + [φ]×`` taking e_k to l (φ = e_k × dl), the rotation
        about l is ``Q R0 Qᵀ = R0 (I + [R0ᵀφ − φ]×)`` to first order.
        """
        e = np.eye(3)[self.direction]
        phi = np.cross(e, -self.tilt)  # dl/ds_d = -e_d for every axis of seed 001
        out = np.zeros((np.size(q), 6))
        out[:, 3:] = _rotate(phi, -(self.sign * q)[:, None] * e) - phi
        return out


@dataclass(frozen=True, eq=False)
class MachineChain:
    """A machine as a multibody chain: tool pose, volumetric error, Jacobians, inverse kinematics.

    Parameters
    ----------
    bodies : tuple of Body
        Bodies 1..n (``bodies[j - 1]`` is body j); parents refer to indices.
    tool : int
        The body carrying the tool (tip at `tool_tip` in its frame).
    workpiece : int
        The body carrying the workpiece (0 = the bed itself).
    axes : tuple of str, optional
        Column order of axis positions q; default: order of first appearance.
    tool_axis : array_like, shape (3,)
        Tool axis V_t in the tool frame (unit vector), default (0, 0, 1).
    tool_tip : array_like, shape (3,)
        Tool tip P_t in the tool frame [mm], default the origin.
    name : str
        A label for reports.
    """

    bodies: tuple
    tool: int
    workpiece: int
    axes: tuple = None
    tool_axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    tool_tip: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = ""

    def __post_init__(self):
        bodies = tuple(self.bodies)
        if not bodies or not all(isinstance(b, Body) for b in bodies):
            raise ValueError("bodies must be a non-empty sequence of Body")
        object.__setattr__(self, "bodies", bodies)
        names = [b.name for b in bodies]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"body names must be unique; repeated: {', '.join(sorted(dup))}")
        lower = self._lower_body_array()
        lower.flags.writeable = False
        object.__setattr__(self, "lower", lower)
        n = len(bodies)
        for label in ("tool", "workpiece"):
            value = getattr(self, label)
            if not isinstance(value, (int, np.integer)) or not (1 if label == "tool" else 0) <= value <= n:
                raise ValueError(f"{label} must be a body index, got {value!r}")
        if self.tool == self.workpiece:  # the tool relative to itself: no motion, no error, nothing to map
            raise ValueError(f"tool and workpiece must be different bodies, got body {self.tool} for both")
        axes = self._axes()
        object.__setattr__(self, "axes", axes)
        v = _validate.finite_array("tool_axis", self.tool_axis, shape=(3,))
        if abs(np.linalg.norm(v) - 1) > _UNIT_TOLERANCE:
            raise ValueError(f"tool_axis must be a unit vector, got {v}")
        v.flags.writeable = False
        object.__setattr__(self, "tool_axis", v)
        tip = _validate.finite_array("tool_tip", self.tool_tip, shape=(3,))
        tip.flags.writeable = False
        object.__setattr__(self, "tool_tip", tip)
        object.__setattr__(self, "tool_chain", self.chain_to(self.tool))
        object.__setattr__(self, "work_chain", self.chain_to(self.workpiece))
        object.__setattr__(self, "arrays", self._arrays())

    def _lower_body_array(self):
        """:func:`lower_body_array` of the bodies' parents, its errors told by the bodies' names."""
        try:
            return lower_body_array([b.parent for b in self.bodies])
        except ChainError as exc:
            names = ["bed", *(b.name for b in self.bodies)]
            parent = self.bodies[exc.body - 1].parent
            if not 0 <= parent <= len(self.bodies):
                raise ChainError(f"body {names[exc.body]!r}: parent {parent} is not a body 0..{len(self.bodies)}",
                                 "parent", exc.body) from None
            cycle = [exc.body]
            while self.bodies[cycle[-1] - 1].parent != exc.body:
                cycle.append(self.bodies[cycle[-1] - 1].parent)
            first = cycle.index(min(cycle))  # told from the cycle's first body
            cycle = cycle[first:] + cycle[:first]
            body = self.bodies[cycle[0] - 1]
            raise ChainError(f"body {body.name!r}: parent = \"{names[body.parent]}\" makes a cycle, "
                             f"{' → '.join(names[k] for k in [*cycle, cycle[0]])} (each body's parent after it): the "
                             "bodies must form a tree on 'bed'", "parent", cycle[0]) from None

    def _axes(self):
        """The column order of q: `axes` checked against the bodies' joints, or the order the bodies drive them in."""
        driven = {}  # axis -> the body it drives
        for j, body in enumerate(self.bodies, start=1):
            if body.axis in driven:  # one servo axis moving two carriages
                raise ChainError(f"axis {body.axis!r} drives two bodies, {driven[body.axis]!r} and {body.name!r}: each "
                                 "axis drives one body", "axis", j)
            if body.axis is not None:
                driven[body.axis] = body.name
        if self.axes is None:
            return tuple(driven)
        axes = tuple(self.axes)
        repeated = [axis for k, axis in enumerate(axes) if axis in axes[:k]]
        missing = [axis for axis in driven if axis not in axes]
        idle = [axis for axis in axes if axis not in driven]
        if repeated or missing:
            what = (f"lists {repeated[0]!r} more than once" if repeated else
                    f"lacks {', '.join(f'{axis!r} (driven by body {driven[axis]!r})' for axis in missing)}")
            raise ChainError(f"axes {what}: it lists each axis a body drives, once ({', '.join(driven)})", "axes")
        if idle:
            raise ChainError(f"axes lists {', '.join(map(repr, idle))}, which no body drives (the bodies drive "
                             f"{', '.join(driven)})", "axes")
        return axes

    def _arrays(self):
        """The chain as flat arrays, one entry per body, for :func:`contoursim._chainkernels.axis_jacobian`."""
        bodies = self.bodies
        return dict(
            parent=np.array([b.parent for b in bodies], np.int64),
            kind=np.array([("fixed", "linear", "rotary").index(b.joint) for b in bodies], np.int64),
            column=np.array([-1 if b.axis is None else self.axes.index(b.axis) for b in bodies], np.int64),
            direction=np.array([b.direction for b in bodies], np.int64),
            sign=np.array([b.sign for b in bodies], float),
            offset=np.array([b.offset for b in bodies], float).reshape(len(bodies), 3),
            # +1 on the tool branch only, -1 on the workpiece branch only, 0 on both (or neither)
            side=np.array([float(j in self.tool_chain) - float(j in self.work_chain) for j in range(1, len(bodies) + 1)]),
            order=np.argsort(np.count_nonzero(self.lower, axis=0), kind="stable").astype(np.int64),
        )

    # -- topology ---------------------------------------------------------

    @property
    def parents(self):
        """Parent index of bodies 1..n, shape (n,)."""
        return np.array([b.parent for b in self.bodies])

    def chain_to(self, j):
        """Bodies from the bed out to body `j` (tuple of indices; empty for the bed)."""
        if _validate.positive_int("j", j, least=0) > len(self.bodies):
            raise ValueError(f"j must be a body index 0..{len(self.bodies)} (0 the bed), got {j}")
        if j == 0:
            return ()
        column = self.lower[:, j - 1]
        return tuple(int(k) for k in column[column > 0][::-1])

    def axis_kind(self, axis):
        """``"linear"`` or ``"rotary"`` for an axis name."""
        if axis not in self.axes:
            raise ValueError(f"axis must be one of the chain's axes ({', '.join(self.axes)}), got {axis!r}")
        return next(b.joint for b in self.bodies if b.axis == axis)

    @property
    def rotary_axes(self):
        """Boolean mask over `axes`: True for rotary axes."""
        return np.array([self.axis_kind(a) == "rotary" for a in self.axes])

    # -- derived chains ---------------------------------------------------

    def ideal(self):
        """The same machine without any error."""
        return self.scaled(0.0)

    def scaled(self, factor):
        """The same machine with every error multiplied by `factor`."""
        return replace(self, bodies=tuple(b.scaled(factor) for b in self.bodies))

    def parameters(self):
        """Every error parameter that is set, ``{name: value}``.

        Names are ``<body>.<dx|dy|dz|ex|ey|ez>.p<k>`` (polynomial coefficient
        [mm or rad per unit of q^k]), ``<body>.<comp>.cyclic<i>.sin|cos``,
        ``<body>.static.<comp>``, ``<body>.squareness.<x|y|z>`` [rad],
        ``<body>.tilt.<x|y|z>`` [rad], ``<body>.thermal.<comp>`` [mm/s, rad/s],
        ``<body>.thermal_growth.<dx|dy|dz>`` [1/s: mm/s per mm].
        Tabulated error motions are data, not parameters.
        """
        out = {}
        for b in self.bodies:
            out.update(b.parameters())
        return out

    def with_parameters(self, values):
        """A copy with the named parameters set (names as in :meth:`parameters`; new ones allowed)."""
        bodies = list(self.bodies)
        for name, value in values.items():
            j, key = self._split(name)
            bodies[j - 1] = bodies[j - 1].with_parameter(key, value)
        return replace(self, bodies=tuple(bodies))

    # -- forward kinematics -----------------------------------------------

    def tool_pose(self, q, t=None, ideal=False):
        """Tool tip and tool axis in workpiece coordinates (exact 4x4 products).

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Axis positions, columns in the order of `axes` [mm for linear,
            rad for rotary axes].
        t : ndarray, shape (N,), optional
            Times [s] for the thermal drift; no drift when omitted.
        ideal : bool
            Evaluate the error-free machine.

        Returns
        -------
        position : ndarray, shape (N, 3)
            Tool tip P_w [mm].
        axis : ndarray, shape (N, 3)
            Tool axis V_w (unit vector).
        """
        q, t = self._check(q, t)
        steps, err, times = self._program(q, t, _validate.flag("ideal", ideal))
        kind, inverse, column, vector = (np.array(x, dtype) for x, dtype in zip(zip(*steps), (np.int64, bool, np.int64, float)))
        pose = _chainkernels.tool_pose(q, times, err, self.tool_tip, self.tool_axis, kind, inverse, column, vector.reshape(-1, 6))
        return pose[:, :3], pose[:, 3:]

    def _program(self, q, t, ideal):
        """The steps of :func:`contoursim._chainkernels.tool_pose` and the error motions they read.

        Body j's transform to its parent is the product of the characteristic
        matrices S ΔS M D E (module docstring), each a step (rotation w, then
        translation d) with w, d fixed or read from q, t or the error
        motions. The tool tip goes out from the tool frame through the tool
        branch's bodies, last step first, then in through the workpiece
        branch's bodies, inverted. A thermal drift in time only is a THERMAL
        step (a time row times the rates); one with a thermal growth depends
        on the axis position too and is a per-sample twist, an ERROR step
        reading its row of `err`.

        Returns
        -------
        steps : list of (kind, inverse, column, vector (6,))
        err : ndarray, shape (M, 6, N)
            Error motions of the moving bodies that have any, then the thermal
            drift of the bodies with a thermal growth [mm, rad].
        times : ndarray, shape (T, N)
            What the thermal drift rates multiply, one row per time constant
            (:meth:`Body.thermal_time`) [s].
        """
        K = _chainkernels
        drifting = [] if ideal or t is None else [j for j, b in enumerate(self.bodies, 1) if b.drifts]
        growing = [j for j in drifting if self.bodies[j - 1].thermal_growth.any()]
        with_errors = [j for j, b in enumerate(self.bodies, 1) if not ideal and b.joint != "fixed" and b.has_motion_error]
        err = np.empty((len(with_errors) + len(growing), 6, q.shape[0]))  # each component contiguous
        for i, j in enumerate(with_errors):
            b = self.bodies[j - 1]
            b.motion_error(q[:, self.axes.index(b.axis)], out=err[i].T)
        for i, j in enumerate(growing, start=len(with_errors)):
            b = self.bodies[j - 1]
            b.thermal_drift(t, q[:, self.axes.index(b.axis)], out=err[i].T)

        drift_times = {}  # time constant -> what the drift rates multiply
        for j in drifting:
            b = self.bodies[j - 1]
            if j not in growing:
                drift_times.setdefault(b.thermal_time_constant, b.thermal_time(t))
        constants = list(drift_times)
        times = np.array(list(drift_times.values())).reshape(len(constants), q.shape[0])

        def body_steps(j):
            b = self.bodies[j - 1]
            steps = [(K.CONSTANT, 0, np.concatenate([np.zeros(3), b.offset]))]
            if not ideal and b.static.any():
                steps.append((K.CONSTANT, 0, np.concatenate([b.static[3:], b.static[:3]])))
            if b.joint == "linear":
                steps.append((K.LINEAR, self.axes.index(b.axis), np.concatenate([np.zeros(3), b.sign * np.eye(3)[b.direction]])))
            elif b.joint == "rotary":
                line = np.eye(3)[b.direction] if ideal else tilted_axis(b.direction, b.tilt)
                steps.append((K.ROTARY, self.axes.index(b.axis), np.concatenate([b.sign * line, np.zeros(3)])))
            if j in growing:
                steps.append((K.ERROR, len(with_errors) + growing.index(j), np.zeros(6)))
            elif j in drifting:
                steps.append((K.THERMAL, constants.index(b.thermal_time_constant), np.concatenate([b.thermal[3:], b.thermal[:3]])))
            if j in with_errors:
                steps.append((K.ERROR, with_errors.index(j), np.zeros(6)))
            return steps

        program = []
        for j in reversed(self.tool_chain):  # tool frame -> bed
            program += [(kind, False, column, vector) for kind, column, vector in reversed(body_steps(j))]
        for j in self.work_chain:  # bed -> workpiece frame
            program += [(kind, True, column, vector) for kind, column, vector in body_steps(j)]
        return program, err, times

    def volumetric_error(self, q, t=None):
        """Actual minus ideal tool pose at the same axis positions.

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Axis positions [mm, rad].
        t : ndarray, shape (N,), optional
            Times [s] (thermal drift).

        Returns
        -------
        position : ndarray, shape (N, 3)
            Volumetric position error [mm].
        axis : ndarray, shape (N, 3)
            Tool-axis error V_w(actual) − V_w(ideal) [rad, small].
        """
        pa, va = self.tool_pose(q, t)
        pi, vi = self.tool_pose(q, t, ideal=True)
        return pa - pi, va - vi

    # -- first-order model ------------------------------------------------

    def _frames(self, q):
        """Ideal poses (R, o) in bed coordinates of every body's static and motion frames."""
        n = q.shape[0]
        static, motion = {0: None}, {0: (np.eye(3)[None], np.zeros((n, 3)))}
        for j in np.argsort(np.count_nonzero(self.lower, axis=0), kind="stable") + 1:
            b = self.bodies[j - 1]
            R, o = motion[b.parent]
            o = o + R @ b.offset
            static[j] = (R, o)
            if b.joint == "linear":
                xi = b.sign * q[:, self.axes.index(b.axis)]
                o = o + xi[:, None] * R[..., b.direction]
            elif b.joint == "rotary":
                xi = b.sign * q[:, self.axes.index(b.axis)]
                w = (xi[:, None] * R[..., b.direction])[:, None, :]
                R = np.swapaxes(_rotate(np.swapaxes(R, -1, -2), w), -1, -2)
            motion[int(j)] = (R, o)
        return static, motion

    def _effects(self, q):
        """A function (body, frame kind, twist) -> first-order change of (P_w, V_w), shape (N, 6).

        The twist (δ, ε), shape (N, 6) or (6,), is given in the coordinates of
        the body's static frame (after S) or motion frame (after M).
        """
        static, motion = self._frames(q)
        R_t, o_t = motion[self.tool]
        p = o_t + R_t @ self.tool_tip
        v = np.broadcast_to(R_t @ self.tool_axis, p.shape)
        R_w = motion[self.workpiece][0]
        sides = {j: 1.0 for j in self.tool_chain} | {j: -1.0 for j in self.work_chain}
        shared = set(self.tool_chain) & set(self.work_chain)

        def effect(j, kind, twist):
            if j in shared:
                return np.zeros((p.shape[0], 6))
            R, o = (static if kind == "static" else motion)[j]
            twist = np.broadcast_to(twist, (p.shape[0], 6))
            d = np.matmul(R, twist[:, :3, None])[..., 0]
            e = np.matmul(R, twist[:, 3:, None])[..., 0]
            dp = d + _cross(e, p - o)
            dv = _cross(e, v)
            back = np.swapaxes(R_w, -1, -2)
            return sides[j] * np.concatenate([np.matmul(back, dp[..., None])[..., 0], np.matmul(back, dv[..., None])[..., 0]], axis=1)

        return effect

    def first_order_error(self, q, t=None):
        """First-order (small-error) volumetric error.

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Axis positions [mm, rad].
        t : ndarray, shape (N,), optional
            Times [s] (thermal drift).

        Returns
        -------
        ndarray, shape (N, 6)
            Position error [mm] (columns 0-2) and tool-axis error (3-5).
        """
        q, t = self._check(q, t)
        effect = self._effects(q)
        out = np.zeros((q.shape[0], 6))
        for j in set(self.tool_chain) ^ set(self.work_chain):
            b = self.bodies[j - 1]
            if b.static.any():
                out += effect(j, "static", b.static)
            qj = None if b.joint == "fixed" else q[:, self.axes.index(b.axis)]
            twist = b.thermal_drift(t, qj) if t is not None and b.drifts else np.zeros((q.shape[0], 6))
            if b.joint != "fixed":
                twist += b.motion_error(qj)
                if b.tilt.any():
                    twist += b.tilt_twist(qj)
            if twist.any():
                out += effect(j, "motion", twist)
        return out

    def error_jacobian(self, q, names=None, t=None):
        """Sensitivity of the volumetric error to error parameters (first order, at zero error).

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Axis positions [mm, rad].
        names : sequence of str, optional
            Parameter names (see :meth:`parameters`; any valid name, set or
            not). Default: the parameters that are set.
        t : ndarray, shape (N,), optional
            Times [s], needed for thermal parameters.

        Returns
        -------
        ndarray, shape (N, 6, P)
            d(P_w, V_w)/d(parameter), columns in the order of `names`.
        """
        q, t = self._check(q, t)
        names = list(self.parameters()) if names is None else list(names)
        effect = self._effects(q)
        n = q.shape[0]
        out = np.zeros((n, 6, len(names)))
        for col, name in enumerate(names):
            j, key = self._split(name)
            b = self.bodies[j - 1]
            group, _, rest = key.partition(".")
            kind = "static" if group == "static" else "motion"
            if b.joint == "fixed" and kind == "motion" and group not in ("thermal", "thermal_growth"):
                raise ValueError(f"{name}: a fixed body has only static errors and thermal drift")
            qj = None if b.joint == "fixed" else q[:, self.axes.index(b.axis)]
            basis = np.zeros((n, 6))
            if group in COMPONENTS:
                basis[:, COMPONENTS.index(group)] = b.motion[COMPONENTS.index(group)].basis(rest, qj)
            elif group == "static" and rest in COMPONENTS:
                basis[:, COMPONENTS.index(rest)] = 1.0
            elif group in ("thermal", "thermal_growth") and rest in COMPONENTS:
                if t is None:
                    raise ValueError(f"{name}: thermal parameters need the times t")
                if group == "thermal":
                    basis[:, COMPONENTS.index(rest)] = b.thermal_time(t)
                elif b.joint == "linear" and COMPONENTS.index(rest) < 3:
                    basis[:, COMPONENTS.index(rest)] = b.thermal_time(t) * (qj - b.thermal_reference)
                else:
                    raise ValueError(f"{name}: thermal growth is dx, dy, dz of a linear joint")
            elif group == "squareness" and rest in _DIRECTIONS and b.joint == "linear":
                if _DIRECTIONS.index(rest) == b.direction:
                    raise ValueError(f"{name}: squareness is towards the other two directions")
                basis[:, _DIRECTIONS.index(rest)] = -b.sign * qj
            elif group == "tilt" and rest in _DIRECTIONS and b.joint == "rotary":
                if _DIRECTIONS.index(rest) == b.direction:
                    raise ValueError(f"{name}: tilt is towards the other two directions")
                unit = replace(b, tilt=np.eye(3)[_DIRECTIONS.index(rest)])
                basis = unit.tilt_twist(qj)
            else:
                raise ValueError(f"unknown parameter {name!r}")
            out[:, :, col] = effect(j, kind, basis)
        return out

    def axis_jacobian(self, q):
        """Sensitivity of the ideal tool pose to the axis positions.

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Axis positions [mm, rad].

        Returns
        -------
        ndarray, shape (N, 6, n_axes)
            d(P_w, V_w)/dq [mm/mm, mm/rad, 1/mm, 1/rad].
        """
        q, _ = self._check(q, None)
        a = self.arrays
        return _chainkernels.axis_jacobian(
            q, len(self.axes), self.tool, self.workpiece, self.tool_tip, self.tool_axis, a["order"], a["parent"],
            a["kind"], a["column"], a["direction"], a["sign"], a["offset"], a["side"],
        )

    # -- inverse kinematics -----------------------------------------------

    def inverse(self, position, tool_axis=None, q0=None, t=None, free=None, ideal=False, tol=1e-10, max_iter=20):
        """Axis positions that put the tool tip (and axis) at a target, by Gauss-Newton iteration.

        Each step solves the least-squares problem with the ideal chain's axis
        Jacobian, position first and the tool axis in the freedom left (see
        :func:`_prioritized_inverse`); on the ideal chain of a Cartesian machine the
        first step is exact (the map is affine), on the actual chain the
        residual shrinks by about the errors' relative size and slope per step. The
        Jacobian is kept while the steps shrink at least tenfold each (as
        they do on the actual chain, whose errors are small) and evaluated
        anew where they do not. The samples are iterated in blocks of
        16 384, each to its own end (its Jacobians and step operators, of
        the block's length, stay in cache).

        Parameters
        ----------
        position : ndarray, shape (N, 3)
            Target tool tip in workpiece coordinates [mm].
        tool_axis : ndarray, shape (N, 3), optional
            Target tool axis (unit vectors). Without it only the position is
            matched and rotary axes stay at `q0`.
        q0 : ndarray, shape (N, n_axes), optional
            Starting positions (zeros by default) [mm, rad].
        t : ndarray, shape (N,), optional
            Times [s] (thermal drift).
        free : sequence of str, optional
            Axes to solve for; the others stay at `q0`. Default: all axes
            when `tool_axis` is given, else the linear axes.
        ideal : bool
            Invert the error-free chain.
        tol : float
            Stop when no axis moves more than this [mm or rad], or when the
            steps still to come are estimated below it: steps shrinking by a
            ratio ρ < 0.1 sum to at most ρ/(1 − ρ) times the last one.
        max_iter : int
            Iteration limit.

        Returns
        -------
        ndarray, shape (N, n_axes)
            Axis positions [mm, rad].

        Raises
        ------
        ValueError
            The iteration does not converge within `max_iter` steps; a
            `tool_axis` row is not a unit vector; `tol` is not positive.
        """
        position = _validate.finite_array("position", position, ndim=2)
        n = position.shape[0]
        _validate.finite_array("position", position, shape=(n, 3))
        if tool_axis is not None:
            tool_axis = _validate.finite_array("tool_axis", tool_axis, shape=(n, 3))
            length = np.linalg.norm(tool_axis, axis=1)
            off = np.abs(length - 1) > _UNIT_TOLERANCE  # matched as it is: (0, 0, 2) moved the rotary axes elsewhere
            if off.any():
                i = int(np.argmax(off))
                raise ValueError(f"tool_axis must hold unit vectors, got {tool_axis[i]} (length {length[i]:g}) at row "
                                 f"{i}")
        q = (np.zeros((n, len(self.axes))) if q0 is None else
             _validate.finite_array("q0", q0, shape=(n, len(self.axes)), limit=_LARGEST_NUMBER))
        q = q.copy()
        t = None if t is None else _validate.finite_array("t", t, shape=(n,))
        if free is None:
            mask = np.ones(len(self.axes), bool) if tool_axis is not None else ~self.rotary_axes
        else:
            unknown = set(free) - set(self.axes)
            if unknown:
                raise ValueError(f"free: unknown axes {sorted(unknown)}; the axes are {list(self.axes)}")
            mask = np.array([a in free for a in self.axes])
        rows = 6 if tool_axis is not None else 3
        columns = np.flatnonzero(mask)
        target_axis = np.zeros((0, 3)) if tool_axis is None else tool_axis
        tol, max_iter = _validate.positive("tol", tol), _validate.positive_int("max_iter", max_iter)
        for part in blocks(n):
            self._newton(q[part], position[part], target_axis[part], None if t is None else t[part], columns, rows, ideal,
                         tol, max_iter, part.start)
        return q

    def _newton(self, q, position, target_axis, t, columns, rows, ideal, tol, max_iter, first):
        """The Gauss-Newton iteration of :meth:`inverse` on one block of samples, `q` updated in place.

        `first` is the block's first sample, for the message of a block that
        does not converge.
        """
        refresh, previous = True, None
        for _ in range(max_iter):
            if refresh:  # a new Jacobian only when the last one stops the steps shrinking fast
                J = self.axis_jacobian(q if self.rotary_axes.any() else q[:1])  # linear axes only: one J for all
                P = _prioritized_inverse(J[:, :rows] if columns.size == J.shape[2] else J[:, :rows].take(columns, axis=2))
                del J
                refresh = False
            p, v = self.tool_pose(q, t, ideal=ideal)
            largest, worst = _chainkernels.newton_update(q, columns, P, p, v, position, target_axis)
            if largest <= tol:
                return
            if previous is not None:
                ratio = largest / previous  # the contraction of a linearly converging iteration ...
                if ratio < 0.1 and largest * ratio / (1 - ratio) <= tol:  # ... bounds the steps still to come
                    return
                refresh = ratio >= 0.1
            previous = None if refresh else largest
        raise ValueError(f"inverse kinematics did not converge in {max_iter} steps (sample {first + worst}, last step {largest:.3g})")

    # -- helpers ----------------------------------------------------------

    def _check(self, q, t):
        # beyond any number a machine file holds, the error motions overflow to NaN; a position beyond the travel is
        # the travel check's to say, naming the work offset or the path (Machine.axis_joints)
        q = _validate.finite_array("q", q, ndim=2, limit=_LARGEST_NUMBER)
        if q.shape[1] != len(self.axes):
            raise ValueError(f"q must have shape (N, {len(self.axes)}) for axes {list(self.axes)}, got {q.shape}")
        if t is not None:
            t = _validate.finite_array("t", t, shape=(q.shape[0],))
        return q, t

    def _split(self, name):
        body, _, key = str(name).partition(".")
        for j, b in enumerate(self.bodies, start=1):
            if b.name == body:
                return j, key
        raise ValueError(f"unknown parameter {name!r}: no body named {body!r}")


def _prioritized_inverse(J, rcond=1e-4):
    """Per-sample least-squares operator P of ``J·step = r`` (step = P r): position rows first, tool axis second.

    The position rows (0-2) are solved in the least-squares sense; the
    tool-axis rows (3-5, if present) only in the null space the position
    leaves free, so an orientation that cannot be reached never costs
    position accuracy. Directions that barely act are dropped instead of
    being sent far away (a rotary axis at a singular pose: C parallel to the
    tool at A = 0, a lathe spindle with the tool on its axis): for the
    position, directions moving the tool less than 10 µm per mm or rad; for
    the tool axis, directions turning it less than 1 % as much as the
    strongest axis does.

    Parameters
    ----------
    J : ndarray, shape (N, 3 or 6, k)
        Axis Jacobian [mm/mm, mm/rad; 1/mm, 1/rad].
    rcond : float
        Eigenvalue threshold of the column-scaled normal equations.

    Returns
    -------
    ndarray, shape (N, k, 3 or 6)
    """
    return _chainkernels.prioritized_inverse(np.ascontiguousarray(J, dtype=float), rcond)


def _rotate(v, w):
    """Rotate vectors `v` (..., 3) by rotation vectors `w` (..., 3) (Rodrigues, exact; broadcasts)."""
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    shape = np.broadcast_shapes(v.shape, w.shape)
    flat = lambda a: np.ascontiguousarray(np.broadcast_to(a, shape)).reshape(-1, 3)
    return _rotate_kernel(flat(v), flat(w)).reshape(shape)


@njit(cache=True)
def _rotate_kernel(v, w):
    """Rows of (M, 3) arrays: v rotated by w (:func:`contoursim._chainkernels.rotated`)."""
    out = np.empty_like(v)
    for n in range(v.shape[0]):
        a, b = _chainkernels.rotation(w[n, 0], w[n, 1], w[n, 2])
        out[n, 0], out[n, 1], out[n, 2] = _chainkernels.rotated(v[n, 0], v[n, 1], v[n, 2], w[n, 0], w[n, 1], w[n, 2], a, b)
    return out


def _cross(a, b):
    """Cross product of broadcastable (..., 3) arrays."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def cartesian_chain(axes=("x", "y", "z")):
    """The error-free chain of a Cartesian machine: each axis moves the tool along its own direction.

    The home of geometric effects on a machine described by its servo axes
    alone: body X on the bed, Y on X, Z on Y, the tool on the last; the
    workpiece is the bed. With zero errors the tool tip is ``(x, y, z)``.

    Parameters
    ----------
    axes : tuple of str
        ``("x",)``, ``("x", "y")`` or ``("x", "y", "z")``.

    Returns
    -------
    MachineChain

    Examples
    --------
    >>> chain = cartesian_chain(("x", "y"))
    >>> chain.tool_pose(np.array([[3.0, 4.0]]))[0].tolist()
    [[3.0, 4.0, 0.0]]
    """
    axes = tuple(axes)
    if axes not in (("x",), ("x", "y"), ("x", "y", "z")):
        raise ValueError(f"a Cartesian chain has axes x, y (, z) in that order, got {axes}")
    bodies = [Body(a.upper(), parent=i, joint="linear", direction=i, axis=a) for i, a in enumerate(axes)]
    bodies.append(Body("tool", parent=len(axes)))
    return MachineChain(tuple(bodies), tool=len(bodies), workpiece=0, axes=axes, name="Cartesian")


# -- TOML machine description ----------------------------------------------

_MACHINE_KEYS = ("name", "description", "tool", "workpiece", "tool_tip_mm", "tool_axis", "axis_order", "body")
_BODY_KEYS = ("name", "parent", "joint", "axis", "travel_mm", "travel_deg", "offset_mm", "static", "squareness", "tilt",
              "thermal", "thermal_growth", "thermal_reference_mm", "thermal_time_constant_s", "errors")
_TERM_KEYS = ("constant", "poly", "cyclic")
#: Keys of earlier versions -> the keys that replaced them.
_RENAMED = {"tool_tip": "tool_tip_mm", "offset": "offset_mm"}


def chain_from_toml(toml, *keys, extra=()):
    """Build a :class:`MachineChain` from a TOML machine description.

    This is the geometric half of a machine file (see
    :func:`contoursim.machine.load_machine`, which also reads the servo
    half). The description reads like the machine; every key carries its
    unit (the section "File format" of docs/machines-and-files.md lists them all)::

        name = "3-axis vertical mill"
        tool = "tool"                 # the body carrying the tool
        workpiece = "table"
        tool_tip_mm = [0, 0, 0]       # optional tip in the tool body's frame
        tool_axis = [0, 0, 1]         # optional
        axis_order = ["x", "y", "z"]  # optional column order of q

        [[body]]
        name = "X"
        parent = "Y"                  # a body name or "bed"
        joint = "linear -x"           # fixed | linear [-]x|y|z | rotary [-]x|y|z
        axis = "x"                    # the commanded axis driving it
        travel_mm = [0, 500]          # travel_deg for a rotary joint
        offset_mm = [0, 0, 0]
        static = { dz_um = 5, ex_urad = 2 }        # assembly error
        squareness = { y_urad = 20 }               # linear joint, positive: angle > 90°
        tilt = { x_urad = 10, y_urad = -5 }        # rotary joint axis-line squareness (seed 001)
        thermal = { dx_um_per_min = 2 }            # drift rate (ex_urad_per_min ...)
        thermal_growth = { dx_ppm_per_min = 1.5 }  # linear joint: the drift rate grows per m of travel
        thermal_reference_mm = 0                   # ... from this axis position (default 0)
        thermal_time_constant_s = 1800             # optional first-order drift (default: linear in time)
        [body.errors]
        table = "x_laser.csv"         # optional ISO 230-2 table, relative to this file
        dx_um = { poly = [0, 12e-3], cyclic = [{ amplitude_um = 1.5, period_mm = 10, phase_deg = 0 }] }
        ey_urad = { constant = 8 }

    An error motion's ``constant`` and ``poly`` are in the unit of its key,
    polynomial coefficients per mm^k (per deg^k for a rotary axis); a cyclic
    term's amplitude is in the same unit and its period in mm (``period_deg``
    for a rotary axis).

    Parameters
    ----------
    toml : contoursim.config.TomlFile
        The parsed file (keeps the text for line numbers in errors).
    *keys : str
        Path of the machine table inside the file (none: the top level).
    extra : iterable of str
        Further keys the machine table may hold (e.g. a job's own section).

    Returns
    -------
    MachineChain

    Raises
    ------
    ConfigError
        Naming the file and line of an unknown key or a bad value; a key of
        an earlier version is named with the key that replaced it.
    """
    top = toml.table(*keys, allowed=_MACHINE_KEYS + tuple(extra), required=("tool", "workpiece", "body"), renamed=_RENAMED,
                     text={**TEXT_KEYS, "tool": "a body's name", "workpiece": "a body's name"})
    raw = top["body"]
    if not isinstance(raw, list) or not raw:
        raise toml.error("body must be an array of tables ([[body]])", *keys, "body")
    names = []
    for i in range(len(raw)):
        travel = "travel_deg" if str(raw[i].get("joint", "")).strip().startswith("rotary") else "travel_mm"
        item = toml.table(*keys, "body", i, allowed=_BODY_KEYS, required=("name",), renamed={**_RENAMED, "travel": travel},
                          text={**TEXT_KEYS, "parent": "a body's name", "joint": "a joint", "axis": "an axis name"})
        if not isinstance(item["name"], str) or item["name"] in names or item["name"] == "bed":
            raise toml.error(f"body name must be a unique string other than 'bed', got {item['name']!r}", *keys, "body", i, "name")
        names.append(item["name"])
    index = {"bed": 0, **{name: j for j, name in enumerate(names, start=1)}}

    def body_index(value, *where):
        if value not in index:
            raise toml.error(f"{value!r} is not a body; expected 'bed' or one of: {', '.join(names)}", *where)
        return index[value]

    base = Path(toml.source).parent
    bodies = [_body_from_toml(toml, base, keys + ("body", i), raw[i], body_index) for i in range(len(raw))]

    def fail(message, *key):
        return toml.error(message, *keys, *key)

    axes = top.get("axis_order")
    if axes is not None and not (isinstance(axes, list) and all(isinstance(axis, str) for axis in axes)):
        raise fail(f"axis_order must be a list of axis names in quotes ([\"x\", \"y\", \"z\"]), got {axes!r}",
                   "axis_order")
    tool = body_index(top["tool"], *keys, "tool")
    workpiece = body_index(top["workpiece"], *keys, "workpiece")
    tool_axis = _vector(top, "tool_axis", [0.0, 0.0, 1.0], fail)
    if not np.linalg.norm(tool_axis) > 0:
        raise fail(f"tool_axis must be a non-zero vector, got {top['tool_axis']!r}", "tool_axis")
    tool_tip = _vector(top, "tool_tip_mm", [0.0, 0.0, 0.0], fail)
    try:
        return MachineChain(
            tuple(bodies),
            tool=tool,
            workpiece=workpiece,
            axes=None if axes is None else tuple(axes),
            tool_axis=tool_axis / np.linalg.norm(tool_axis),
            tool_tip=tool_tip,
            name=str(top.get("name", Path(toml.source).stem)),
        )
    except ChainError as exc:  # at the key's line: the body's parent or axis, or axis_order
        if exc.body is None:
            raise fail("axis_order" + str(exc).removeprefix(exc.key), "axis_order") from None
        raise fail(str(exc), "body", exc.body - 1, exc.key) from None
    except ValueError as exc:
        raise fail(str(exc)) from None


def _body_from_toml(toml, base, where, item, body_index):
    def fail(message, *key):
        return toml.error(f"body {item['name']!r}: {message}", *where, *key)

    joint = _JOINT.match(str(item.get("joint", "fixed")))
    if not joint or (joint.group(1) != "fixed") != (joint.group(3) is not None):
        raise fail(f"joint must be 'fixed', 'linear [-]x|y|z' or 'rotary [-]x|y|z', got {item.get('joint')!r}", "joint")
    kind = joint.group(1)
    rotary = kind == "rotary"
    direction = _DIRECTIONS.index(joint.group(3)) if joint.group(3) else 2
    if (kind == "fixed") != ("axis" not in item):
        raise fail("a moving joint needs 'axis' (the commanded axis name), a fixed one has none", "joint")

    def vector(key, units):
        """A table like ``{ dx_um = 2, ex_urad = 1 }`` in mm, rad; `units` is ((name, unit, scale), ...)."""
        if not isinstance(item.get(key, {}), dict):
            raise fail(f"{key} must be a table like {{ {units[0][0]}_{units[0][1]} = ... }}", key)
        names = [f"{name}_{unit}" for name, unit, _ in units]
        value = toml.table(*where, key, allowed=names, renamed=dict(zip((n for n, _, _ in units), names))) if key in item else {}
        out = np.zeros(len(units))
        for k, v in value.items():
            out[names.index(k)] = _number(v, fail, key) * units[names.index(k)][2]
        return out

    per_min = 1 / 60.0
    static = vector("static", [(c, unit, scale) for c, (unit, scale) in zip(COMPONENTS, ERROR_UNITS)])
    squareness = vector("squareness", [(d, "urad", _RAD_PER_URAD) for d in _DIRECTIONS])
    tilt = vector("tilt", [(d, "urad", _RAD_PER_URAD) for d in _DIRECTIONS])
    thermal = vector("thermal", [(c, f"{unit}_per_min", scale * per_min) for c, (unit, scale) in zip(COMPONENTS, ERROR_UNITS)])
    growth = vector("thermal_growth", [(c, "ppm_per_min", 1e-6 * per_min) for c in COMPONENTS[:3]])
    if growth.any() and kind != "linear":
        raise fail("thermal_growth applies to a linear joint (it grows with the axis position)", "thermal_growth")
    time_constant = _number(item.get("thermal_time_constant_s", 0.0), fail, "thermal_time_constant_s")
    if time_constant < 0:
        raise fail(f"thermal_time_constant_s must be 0 (linear in time) or positive, got {time_constant:g}", "thermal_time_constant_s")
    for key, values, wanted in (("squareness", squareness, "linear"), ("tilt", tilt, "rotary")):
        if values.any() and (kind != wanted or values[direction]):
            raise fail(f"{key} applies to a {wanted} joint, towards the other two directions", key)
    offset = _vector(item, "offset_mm", [0.0, 0.0, 0.0], fail)
    travel_key, wrong = ("travel_deg", "travel_mm") if rotary else ("travel_mm", "travel_deg")
    if wrong in item:
        raise fail(f"the travel of a {kind} joint is '{travel_key}'", wrong)
    travel = item.get(travel_key)
    if travel is not None:
        if not isinstance(travel, list) or len(travel) != 2:
            raise fail(f"{travel_key} must be [min, max]", travel_key)
        travel = [_number(v, fail, travel_key) for v in travel]
        try:  # within the chain's ±MAX_TRAVEL [mm or rad], said in the key's unit
            travel = tuple(_validate.within(travel_key, v, -MAX_TRAVEL, MAX_TRAVEL, np.pi / 180 if rotary else 1.0)
                           for v in travel)
        except ValueError as exc:
            raise fail(str(exc), travel_key) from None
        if not travel[0] < travel[1]:
            raise fail(f"{travel_key} must be [min, max] with min < max, got {item[travel_key]}", travel_key)
    motion = _motion_from_toml(toml, base, where, item, rotary, travel, fail)
    try:
        body = Body(
            name=item["name"],
            parent=body_index(item.get("parent", "bed"), *where, "parent"),
            joint=kind,
            direction=direction,
            sign=-1 if joint.group(2) == "-" else 1,
            axis=item.get("axis"),
            offset=offset,
            static=static,
            motion=motion,
            squareness=squareness,
            tilt=tilt,
            thermal=thermal,
            thermal_growth=growth,
            thermal_reference=_number(item.get("thermal_reference_mm", 0.0), fail, "thermal_reference_mm"),
            thermal_time_constant=time_constant,
            travel=travel,
        )
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise fail(str(exc).removeprefix(f"{item['name']}: ")) from None
    _check_small_errors(body, fail)
    return body


def _check_small_errors(body, fail):
    """Refuse error motions that leave the small errors the chain's model is for (:data:`SMALL_ERROR`) over the travel,
    and a static error's or a rotary axis's tilt's angles beyond it (the chain's rotations are first-order in them)."""
    for key, angles, names in (("static", body.static[3:], COMPONENTS[3:]), ("tilt", body.tilt, ("x", "y", "z"))):
        c = int(np.argmax(np.abs(angles)))
        if abs(angles[c]) > SMALL_ERROR:
            raise fail(f"its {key} angle {names[c]} is {1e6 * angles[c]:.4g} µrad: beyond the small errors a machine's "
                       f"model is for ({SMALL_ERROR:g} an angle); check the units (µrad)", key)
    if body.travel is None or not body.has_motion_error:
        return
    q = np.linspace(*body.travel, 201)
    error = np.abs(body.motion_error(q))
    beyond = _beyond_small_errors(body, error)
    if beyond is not None:
        k, c, size, what = beyond
        at = f"{np.rad2deg(q[k]):g}°" if body.joint == "rotary" else f"{q[k]:g} mm"
        # a linear joint's squareness enters its error motion towards that direction (it was blamed on the table)
        square = body.squareness[c] * q[k] if c < 3 and body.joint == "linear" else 0.0
        source = (f" ({1e3 * abs(square):.4g} µm of it from its squareness {_DIRECTIONS[c]}_urad = "
                  f"{1e6 * body.squareness[c]:.4g})" if square else "")
        mostly = bool(abs(square) > 0.5 * error[k, c])  # said by the squareness's line, where it is most of it
        raise fail(f"its error motion {COMPONENTS[c]} reaches {size} at {at} of its travel{source}: beyond the small "
                   f"errors a machine's model is for ({SMALL_ERROR:g} {what}); check the "
                   f"{'squareness' if mostly else 'coefficients'}' units and the travel", *(("squareness",) * mostly))


def check_drift(chain, duration):
    """Refuse a chain whose thermal drift leaves the small errors its model is for (:data:`SMALL_ERROR`) in a run.

    The error motions are checked so when a machine file is read; the drift
    grows with time, so a run checks it over its length (at the ends of
    each body's travel, where a thermal growth is largest).

    Parameters
    ----------
    chain : MachineChain
    duration : float
        Length of the run [s].

    Raises
    ------
    ValueError
        Naming the body, the drift's component and its size after `duration`.
    """
    for body in chain.bodies:
        if not body.drifts:
            continue
        q = np.zeros(1) if body.travel is None else np.asarray(body.travel, float)
        beyond = _beyond_small_errors(body, np.abs(body.thermal_drift(np.full(q.size, float(duration)), q)))
        if beyond is not None:
            k, c, size, what = beyond
            raise ValueError(f"the machine's body {body.name!r}: its thermal drift {COMPONENTS[c]} reaches {size} "
                             f"after the run's {duration:.6g} s: beyond the small errors a machine's model is for "
                             f"({SMALL_ERROR:g} {what}); check the drift rates' units (per minute)")


def _beyond_small_errors(body, error):
    """``(row, component, "size unit", limit's words)`` of the largest of `error` (N, 6) [mm, rad] beyond
    :data:`SMALL_ERROR` (angles; translations of a linear joint with a travel, per its length), or None."""
    limits = [(3, 6, SMALL_ERROR, 1e6, "µrad", "an angle")]
    if body.joint == "linear" and body.travel is not None:
        limits.append((0, 3, SMALL_ERROR * (body.travel[1] - body.travel[0]), 1e3, "µm", "of the travel's length"))
    for first, last, limit, scale, unit, what in limits:
        k, c = np.unravel_index(np.argmax(error[:, first:last]), (error.shape[0], last - first))
        if error[k, first + c] > limit:
            return k, first + c, f"{scale * error[k, first + c]:.4g} {unit}", what
    return None


def _motion_from_toml(toml, base, where, item, rotary, travel, fail):
    errors = item.get("errors", {})
    if not errors:
        return (ErrorMotion(),) * 6
    keys = {column: comp for column, (comp, _) in ERROR_COLUMNS.items()}  # the same names as an error table's columns
    toml.table(*where, "errors", allowed=(*keys, "table"), renamed={comp: key for key, comp in keys.items()},
               text={"table": "a file name"})
    tables = {}
    if "table" in errors:
        path = base / str(errors["table"])
        try:
            tables = read_error_table(path, rotary=rotary)
        except ConfigError as exc:
            if not path.exists():
                raise fail(f"error table {str(errors['table'])!r} not found (relative to {base})", "errors", "table") from None
            if exc.line is None:  # the table as a whole (a folder, unreadable): said at the line naming it too
                raise fail(f"error table {str(errors['table'])!r}: {exc}", "errors", "table") from None
            raise
        _table_against_travel(str(errors["table"]), tables, travel, rotary, fail)
    to_q = np.pi / 180 if rotary else 1.0  # config position unit -> internal
    period_key = "period_deg" if rotary else "period_mm"
    motion = []
    for key, (unit, scale) in zip(keys, ERROR_UNITS):
        comp = keys[key]
        spec = errors.get(key, {})
        if not isinstance(spec, dict):
            raise fail(f"errors.{key} must be a table of constant / poly / cyclic", "errors", key)
        if spec:
            toml.table(*where, "errors", key, allowed=_TERM_KEYS)
        if "constant" in spec and "poly" in spec:
            raise fail(f"errors.{key}: give either constant or poly, not both", "errors", key)
        poly = spec.get("poly", [spec["constant"]] if "constant" in spec else [])
        if not isinstance(poly, list):
            raise fail(f"errors.{key}.poly must be a list of coefficients", "errors", key)
        poly = [_number(c, fail, "errors", key) * scale / to_q**k for k, c in enumerate(poly)]
        cyclic = spec.get("cyclic", [])
        cyclic = [cyclic] if isinstance(cyclic, dict) else cyclic
        amplitude_key = f"amplitude_{unit}"
        terms = []
        for term in cyclic:
            if not isinstance(term, dict) or set(term) - {amplitude_key, period_key, "phase_deg"} or not {amplitude_key, period_key} <= set(term):
                raise fail(f"errors.{key}.cyclic terms are {{ {amplitude_key}, {period_key}, phase_deg }} "
                           f"(see {FORMAT_DOC})", "errors", key)
            period = _number(term[period_key], fail, "errors", key)
            if period <= 0:
                raise fail(f"errors.{key}.cyclic {period_key} must be positive, got {period}", "errors", key)
            terms.append(Cyclic.from_amplitude(_number(term[amplitude_key], fail, "errors", key) * scale,
                                               period * to_q, np.deg2rad(_number(term.get("phase_deg", 0.0), fail, "errors", key))))
        motion.append(ErrorMotion(tuple(poly), tuple(terms), tables.get(comp)))
    return tuple(motion)


def _table_against_travel(name, tables, travel, rotary, fail):
    """Refuse the error table `name` (`tables`, read by :func:`read_error_table`) where its positions lie beyond any
    travel (:data:`MAX_TRAVEL`), span a hundred times the axis's travel or more (positions in µm, or of another
    machine) or cover none of it; warn when it does not cover all of it.

    Beyond its ends the table's first and last values are held (``np.interp``): an error the table
    does not give, which the user is told of rather than left to find in the results.
    """
    if not tables:
        return
    positions = next(iter(tables.values()))[0]  # every column shares the table's positions
    unit, shown = ("°", np.rad2deg) if rotary else (" mm", np.asarray)
    lo, hi = shown([positions[0], positions[-1]])
    if max(abs(lo), abs(hi)) > MAX_TRAVEL:
        raise fail(f"error table {name!r} holds positions up to {max(abs(lo), abs(hi)):g}{unit}, beyond any travel "
                   f"(±{MAX_TRAVEL:g}{unit})", "errors", "table")
    if travel is None:
        return
    start, end = shown(travel)
    if hi - lo >= 100 * (end - start):  # its rows a hundred travels apart: only its first or last value would apply
        raise fail(f"error table {name!r} spans {lo:g} .. {hi:g}{unit}, {(hi - lo) / (end - start):.3g} times the "
                   f"travel {start:g} .. {end:g}{unit}: positions in µm (or of another axis)?", "errors", "table")
    if positions[0] <= travel[0] and positions[-1] >= travel[1]:
        return
    if positions[-1] < travel[0] or positions[0] > travel[1]:  # held values alone: the table's errors never apply
        raise fail(f"error table {name!r} covers {lo:g} .. {hi:g}{unit}, none of the travel {start:g} .. {end:g}{unit}: "
                   "positions of another axis, or a sign or unit wrong?", "errors", "table")
    message = (f"error table {name!r} covers {lo:g} .. {hi:g}{unit} of the travel {start:g} .. {end:g}{unit}: its first and "
               "last values are held beyond its ends (add rows at the travel's ends to give the errors there)")
    warnings.warn(str(fail(message, "errors", "table")), ContoursimWarning, stacklevel=2)


def _vector(table, key, default, fail):
    """``table[key]`` (or `default`) as an array of 3 finite numbers, refused at the key's line otherwise."""
    value = table.get(key, default)
    if not isinstance(value, list) or len(value) != 3:
        raise fail(f"{key} must be [x, y, z], got {value!r}", key)
    return np.array([_number(v, fail, key) for v in value])


def _number(value, fail, *key):
    name = ".".join(key)  # as the file writes it: offset_mm, errors.dx_um
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise fail(f"{name}: expected a finite number, got {value!r}", *key)
    if abs(value) > _LARGEST_NUMBER:  # 1e308 overflows the error motions and the chain's products
        raise fail(f"{name}: {value:g} is beyond ±{_LARGEST_NUMBER:g}, not a value a machine has", *key)
    return float(value)
