"""The ``contoursim volumetric MACHINE`` job: volumetric error over the workspace.

Evaluates the machine's volumetric error (actual minus ideal tool tip and
tool axis, in workpiece coordinates) on a grid of axis positions spanning the
travels, the rotary axes turned over theirs, prints the worst errors per
component and plots the error field: magnified arrows and colour maps, one
figure per plane of linear axes, the rotary axes where the error is worst.

A rotary axis whose travel spans a turn or more is looked at over one turn,
its positions evenly spread without the end (the start again), when its error
motions repeat every turn (:meth:`~contoursim.errormotion.ErrorMotion.repeats_every`):
the rest of the travel repeats that turn, and positions spread over the
whole travel would be whole turns apart, one angle looked at many times
(``travel_deg = [0, 36000]`` at 5 positions: C = 0° only). Error motions
that do not repeat (a polynomial beyond the constant, an error table, a
cyclic term whose period is no whole fraction of a turn) are looked at over
the whole travel, as many positions a turn.
"""

from itertools import combinations, product

import numpy as np

from . import _memory, _validate
from .exceptions import ConfigError
from .output import output_dir
from .machine import Machine, load_machine
from .multibody import MAX_TRAVEL, MachineChain
from .plotting import magnification_for

__all__ = ["volumetric_grid", "volumetric_report"]

_TURN = 2 * np.pi  # [rad]
#: Most positions at which a rotary axis whose errors do not repeat every turn is looked at over its travel.
MAX_ROTARY_POSITIONS = 10_000


def volumetric_grid(chain, sweep=None, points=11, ranges=None, fixed=None):
    """Axis positions on a grid spanning the workspace.

    Parameters
    ----------
    chain : MachineChain
        The machine.
    sweep : sequence of str, optional
        Axes to sweep; default the linear axes.
    points : int
        Grid points per swept axis (>= 2).
    ranges : dict, optional
        ``{axis: (min, max)}`` [mm or rad], min < max; default the axes' travels, a
        rotary axis's of a turn or more looked at as :func:`volumetric_report`
        says (over one turn, or `points` positions a turn).
    fixed : dict, optional
        ``{axis: position}`` for the other axes [mm or rad]; default 0.

    Returns
    -------
    q : ndarray, shape (M, n_axes)
        Axis positions [mm, rad], the swept axes varying as ``np.meshgrid(..., indexing="ij")``;
        M the product of the lengths of `axes` (``points**len(sweep)`` but for a rotary axis
        looked at over many turns).
    axes : tuple of ndarray
        The grid values of each swept axis.

    Raises
    ------
    ValueError
        A bad argument, an axis to sweep without travel or range, or a rotary axis whose
        errors do not repeat every turn over more positions than :data:`MAX_ROTARY_POSITIONS`.
    """
    if not isinstance(chain, MachineChain):
        raise TypeError(f"chain must be a MachineChain (a machine's .chain), got {type(chain).__name__}")
    sweep = _swept(chain, sweep)
    unknown = set(sweep) - set(chain.axes)
    if unknown or not sweep:
        raise ValueError(f"sweep must name some of the axes {list(chain.axes)}, got {sweep}")
    points = _validate.positive_int("points", points, least=2)
    travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
    ranges, fixed = _positions(chain, ranges, fixed, sweep, travel)
    values = []
    for a in sweep:
        lohi = ranges.get(a, travel[a])
        if lohi is None:
            raise ValueError(f"axis {a!r} has no travel: give its range")
        rotary = a not in ranges and chain.axis_kind(a) == "rotary"
        values.append(_rotary_positions(chain, a, points)[0] if rotary else np.linspace(lohi[0], lohi[1], points))
    sizes = [v.size for v in values]
    _memory.check(np.prod(np.array(sizes, dtype=float)), f"points = {points}: a grid of {' x '.join(map(str, sizes))} "
                  "positions:", "give fewer points (or sweep fewer axes)")
    mesh = np.meshgrid(*values, indexing="ij")
    q = np.zeros((mesh[0].size, len(chain.axes)))
    for a, v in fixed.items():
        q[:, chain.axes.index(a)] = v
    for a, m in zip(sweep, mesh):
        q[:, chain.axes.index(a)] = m.ravel()
    return q, tuple(values)


def _positions(chain, ranges, fixed, sweep, travel):
    """`ranges` ``{axis: (min, max)}`` and `fixed` ``{axis: position}`` of :func:`volumetric_grid`, checked: axes of
    the chain (a range of an axis not swept, a fixed axis that is swept, would be ignored), finite positions within
    ±:data:`~contoursim.multibody.MAX_TRAVEL`, a range's min below its max, a fixed one within its axis's travel."""
    ranges, fixed = dict(ranges or {}), dict(fixed or {})
    for a, span in ranges.items():
        if a not in sweep:
            raise ValueError(f"ranges: axis {a!r} is not swept (sweep: {', '.join(sweep)}): its range would be ignored")
        lo, hi = _validate.finite_array(f"ranges[{a!r}]", span, shape=(2,), limit=MAX_TRAVEL).tolist()
        if not lo < hi:  # a grid running backwards, or one position `points` times
            raise ValueError(f"ranges[{a!r}] must be (min, max) of axis {a} with min < max, got ({lo:g}, {hi:g})")
        ranges[a] = (lo, hi)
    for a, position in fixed.items():
        if a not in chain.axes:
            raise ValueError(f"fixed: unknown axis {a!r}")
        if a in sweep:
            raise ValueError(f"fixed: axis {a!r} is swept (sweep: {', '.join(sweep)}): its position would be ignored")
        fixed[a] = _validate.within(f"fixed[{a!r}]", position, -MAX_TRAVEL, MAX_TRAVEL)
        lo, hi = travel.get(a) or (-MAX_TRAVEL, MAX_TRAVEL)
        if not lo - 1e-9 <= fixed[a] <= hi + 1e-9:
            as_given = f"{fixed[a]:g} mm" if chain.axis_kind(a) == "linear" else f"{fixed[a]:g} rad ({np.degrees(fixed[a]):g}°)"
            raise ValueError(f"fixed[{a!r}] = {as_given} lies outside the travel of axis {a}, {_span(np.array([lo, hi]), chain.axis_kind(a) == 'rotary')}")
    return ranges, fixed


def _rotary_positions(chain, axis, count, source=None):
    """Positions [rad] at which the rotary `axis` is looked at over its travel, and what the summary says of them.

    Under a turn, `count` spanning the travel; over a turn or more, `count`
    over one turn from the travel's start when the axis's error motions
    repeat every turn, else `count` a turn over the whole travel (at most
    :data:`MAX_ROTARY_POSITIONS`: a ConfigError naming `source`, the machine file, beyond).
    """
    body = next(b for b in chain.bodies if b.axis == axis)
    lo, hi = body.travel
    turns = (hi - lo) / _TURN
    if turns < 1 - 1e-9:
        return np.linspace(lo, hi, count), ""
    travel = f"its travel {_span(np.array([lo, hi]), True)}"
    if all(m.repeats_every(_TURN) for m in body.motion):
        return lo + _TURN / count * np.arange(count), f" (one turn of {travel}: its errors repeat every turn)"
    n = int(np.ceil(turns * count - 1e-9)) + 1
    if n > MAX_ROTARY_POSITIONS:
        raise ConfigError(f"axis {axis!r} (body {body.name!r}): its errors do not repeat every turn (a polynomial "
                          f"beyond the constant, an error table, or a cyclic term whose period is no whole fraction "
                          f"of a turn), so each of the {turns:.6g} turns of {travel} is looked at, {count} positions "
                          f"a turn: {n} positions, more than {MAX_ROTARY_POSITIONS}; give it a shorter travel_deg, "
                          "or hold it (volumetric_report's fixed)", source)
    return np.linspace(lo, hi, n), f" ({count} a turn: its errors do not repeat every turn)"


def _swept(chain, sweep):
    """The axes to sweep: `sweep`, or by default the linear axes."""
    return [a for a, rot in zip(chain.axes, chain.rotary_axes) if not rot] if sweep is None else list(sweep)


def volumetric_report(machine, out_dir=None, grid=11, sweep=None, ranges=None, fixed=None, time=0.0, rotary_grid=5):
    """Worst volumetric errors over the workspace, and error-field plots.

    The grid of the `sweep` axes is evaluated at every combination of
    `rotary_grid` positions spanning the travel of each other rotary axis
    (one not in `fixed`), so the worst errors are those of the whole
    workspace; the plots show the plane of each pair of swept axes with the
    rotary axes where the position error |Δ| is worst, and say where.

    A rotary axis whose travel spans a turn or more is looked at over one
    turn, `rotary_grid` positions ``360°/rotary_grid`` apart from the
    travel's start, when its error motions repeat every turn (no polynomial
    term beyond the constant, no error table, every cyclic term's period a
    whole fraction of a turn): the rest of the travel repeats that turn
    (positions spread over ``[0, 36000]°`` would all be C = 0°). Otherwise
    every turn differs and the whole travel is looked at, `rotary_grid`
    positions a turn (at most :data:`MAX_ROTARY_POSITIONS`). The summary says
    which.

    Parameters
    ----------
    machine : str, Path, Machine or MachineChain
        A machine preset name or machine file with a geometric half
        (``[[body]]``), such a machine, or its chain itself.
    out_dir : str, Path or contoursim.output.OutputDir, optional
        Output folder for the PNG plots (see :func:`contoursim.output.output_dir`:
        created if missing; a file there that contoursim did not write is
        never replaced); no plots when omitted.
    grid : int
        Grid points per swept axis.
    sweep : sequence of str, optional
        Axes to sweep; default the linear axes, over their travels.
    ranges : dict, optional
        ``{axis: (min, max)}`` [mm or rad] instead of the travels.
    fixed : dict, optional
        ``{axis: position}`` of the other axes [mm or rad]; default 0.
    time : float
        Time [s] at which the thermal drift is evaluated.
    rotary_grid : int
        Positions per rotary axis outside `sweep` and `fixed` (>= 2; 0 holds
        them at 0, as the output then says); per turn over a travel of a turn
        or more (see above).

    Returns
    -------
    str
        The summary table.

    Raises
    ------
    ConfigError
        The machine file is bad or has no geometric half, a rotary axis's errors do not
        repeat every turn over more positions than :data:`MAX_ROTARY_POSITIONS`, or
        `out_dir` cannot be used.
    FileExistsError
        A plot's file exists in `out_dir` and contoursim did not write it.
    """
    if isinstance(machine, MachineChain):
        chain = machine
    else:
        where = machine.name if isinstance(machine, Machine) else str(machine)
        chain = (machine if isinstance(machine, Machine) else load_machine(machine)).chain
        if chain is None:
            raise ConfigError("the machine has no geometric half ([[body]] tables): nothing to map", where)
        travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
        bare = [a for a in _swept(chain, sweep) if travel[a] is None and a not in (ranges or {})]
        if bare:  # the file's, not an argument's
            raise ConfigError(f"axis {bare[0]!r} has no travel: give its body travel_mm (or travel_deg) to map it",
                              where)
    q, values = volumetric_grid(chain, sweep, grid, ranges, fixed)
    sweep = _swept(chain, sweep)
    rotary = dict(zip(chain.axes, chain.rotary_axes))
    travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
    turned = [a for a in chain.axes if rotary[a] and a not in sweep and a not in (fixed or {})]
    rotary_grid = _validate.positive_int("rotary_grid", rotary_grid, least=0)
    if rotary_grid == 1:
        raise ValueError(f"rotary_grid must be 0 (hold the rotary axes at 0) or at least 2, got {rotary_grid}")
    turned = [a for a in turned if travel.get(a) is not None] if rotary_grid else []
    source = None if isinstance(machine, MachineChain) else str(machine)
    angles, notes = zip(*[_rotary_positions(chain, a, rotary_grid, source) for a in turned]) if turned else ((), ())
    t = np.full(q.shape[0], _validate.finite("time", time))
    columns = [chain.axes.index(a) for a in turned]
    rows, largest = None, -1.0
    for setting in product(*angles):  # one grid of the swept axes at a time: memory as without rotary axes
        q[:, columns] = setting
        dp, dv = chain.volumetric_error(q, t)
        rows = _worst(rows, dp, dv, q)
        if rows[3][1] > largest:  # the largest |Δ| so far: the setting the plots show
            largest, shown = rows[3][1], (setting, dp)
    rotaries = _rotaries(chain, sweep, fixed, turned, angles, notes)
    text = _summary(chain, rows, sweep, values, float(time), rotary, rotaries, len(q) * max(1, len(list(product(*angles)))))
    if out_dir is not None:
        out = output_dir(out_dir)
        setting, dp = shown
        q[:, columns] = setting
        ideal = chain.tool_pose(q, t, ideal=True)[0]
        at = [_at(a, v, True) for a, v in zip(turned, setting)]
        note = f"{', '.join(at)}, where |Δ| is worst" if at else ""
        files = _plot(chain, ideal, dp, sweep, values, rotary, out, note)
        text += f"\nplots{' at ' + note if note else ''}: " + ", ".join(str(f) for f in files) + "\n"
    return text


def _fmt_q(chain, q, rotary):
    return ", ".join(f"{a}={np.rad2deg(v):.1f}°" if rotary[a] else f"{a}={v:.1f} mm" for a, v in zip(chain.axes, q))


def _worst(rows, dp, dv, q):
    """The summary rows ``[label, worst, min, max, axis positions of the worst]`` updated with errors `dp`, `dv` at `q`."""
    components = [(f"position {c} [µm]", 1e3 * dp[:, i]) for i, c in enumerate("xyz")]
    components.append(("position |Δ| [µm]", 1e3 * np.linalg.norm(dp, axis=1)))
    components += [(f"tool axis {c} [µrad]", 1e6 * dv[:, i]) for i, c in enumerate("xyz")]
    new = []
    for (label, v), row in zip(components, rows or [None] * len(components)):
        k = int(np.argmax(np.abs(v)))
        low, high = float(v.min()), float(v.max())
        worst, at = (float(v[k]), q[k].copy()) if row is None or abs(v[k]) > abs(row[1]) else (row[1], row[4])
        if row is not None:
            low, high = min(low, row[2]), max(high, row[3])
        new.append([label, worst, low, high, at])
    return new


def _rotaries(chain, sweep, fixed, turned, angles, notes):
    """What the summary says of the rotary axes outside `sweep`: turned over their travels (`notes`: how), or held."""
    parts = [f"{a} {_span(v, True)} at {len(v)} positions{note}" for a, v, note in zip(turned, angles, notes)]
    held = [a for a, rot in zip(chain.axes, chain.rotary_axes) if rot and a not in sweep and a not in turned]
    if held:
        parts.append("held: " + ", ".join(_at(a, (fixed or {}).get(a, 0.0), True) for a in held))
    return "; rotary axes " + "; ".join(parts) if parts else ""


def _summary(chain, rows, sweep, values, time, rotary, rotaries, count):
    lines = [
        f"volumetric error of {chain.name or 'machine'}",
        f"grid: {count} points over " + ", ".join(f"{a} {_span(v, rotary[a])}" for a, v in zip(sweep, values))
        + rotaries + (f", t = {time:g} s" if time else ""),
        "",
        f"{'component':20s} {'worst':>10s} {'min':>10s} {'max':>10s}  at (axis positions)",
    ]
    for label, worst, low, high, at in rows:
        worst, low, high = (round(v, 3) + 0.0 for v in (worst, low, high))  # a rounding's -1e-12 is 0, not -0.000
        lines.append(f"{label:20s} {worst:+10.3f} {low:+10.3f} {high:+10.3f}  {_fmt_q(chain, at, rotary)}")
    return "\n".join(lines) + "\n"


def _span(v, rot):
    lo, hi = (np.rad2deg(v[[0, -1]]) if rot else v[[0, -1]])
    return f"{lo:g}..{hi:g}{'°' if rot else ' mm'}"


_EXTREME_ASPECT = 5.0  # a plane whose sides differ more than this is drawn stretched, not to scale


def _at(axis, value, rotary):
    """``axis = value`` with its unit: mm, or degrees for a rotary axis (given in rad)."""
    return f"{axis} = {np.rad2deg(value):g}°" if rotary else f"{axis} = {value:g} mm"


def _plot(chain, ideal, dp, sweep, values, rotary, out, note=""):
    """One figure per pair of swept axes (middle of the others): arrows and colour maps.

    `note` says where the rotary axes outside the sweep are, in each title.

    A plane is drawn to scale (equal aspect) unless its sides differ by more
    than :data:`_EXTREME_ASPECT` (e.g. 4000 x 150 mm), where the panels are
    stretched to be readable and say so. Colour bars are as tall as their plots.
    """
    from matplotlib.figure import Figure

    shape = tuple(len(v) for v in values)
    P = ideal.reshape(shape + (3,))
    D = 1e3 * dp.reshape(shape + (3,))
    pairs = list(combinations(range(len(sweep)), 2)) or [(0, None)]  # each plane (the first three of 4 axes were kept)
    files = [out.file(f"volumetric_{sweep[i]}{'' if j is None else sweep[j]}.png") for i, j in pairs]
    for (i, j), name in zip(pairs, files):
        index = [s // 2 for s in shape]
        index[i] = slice(None)
        if j is not None:
            index[j] = slice(None)
        Pp, Dp = P[tuple(index)], D[tuple(index)]
        if j is None:
            fig = Figure(figsize=(7, 4), layout="constrained")
            ax = fig.add_subplot()
            rot = rotary[sweep[0]]
            for c in range(3):
                ax.plot(np.rad2deg(values[0]) if rot else values[0], Dp[:, c], label=f"Δ{'xyz'[c]}")
            ax.set_xlabel(f"axis {sweep[0]} [{'°' if rot else 'mm'}]")
            ax.set_title(f"{chain.name}: volumetric error, axis {sweep[0]} swept" + (f"\n{note}" if note else ""))
            ax.set_ylabel("volumetric error [µm]")
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
        else:
            spread = np.ptp(Pp.reshape(-1, 3), axis=0)
            u, w = np.argsort(spread)[::-1][:2]
            u, w = sorted((u, w))
            X, Y = Pp[..., u], Pp[..., w]
            sides = sorted((np.ptp(X), np.ptp(Y)))
            to_scale = sides[1] <= _EXTREME_ASPECT * sides[0]
            scale_note = "" if to_scale else \
                f"stretched, not to scale: {'xyz'[u]} spans {np.ptp(X):.4g} mm, {'xyz'[w]} {np.ptp(Y):.4g} mm"
            ratio = np.ptp(Y) / np.ptp(X) if to_scale else 0.75  # of each panel's height to its width
            fig = Figure(figsize=(11, min(9.0, 2 * (4.2 * ratio + 0.9) + 0.8)), layout="constrained")
            biggest = np.max(np.hypot(Dp[..., u], Dp[..., w])) * 1e-3
            mag = magnification_for(sides[1] if to_scale else sides[0], biggest)
            axs = fig.subplots(2, 2)
            ax = axs[0, 0]
            ax.plot(X, Y, color="0.8", lw=0.6)
            ax.plot(X.T, Y.T, color="0.8", lw=0.6)
            Xa, Ya = X + mag * 1e-3 * Dp[..., u], Y + mag * 1e-3 * Dp[..., w]
            ax.plot(Xa, Ya, color="C3", lw=0.8)
            ax.plot(Xa.T, Ya.T, color="C3", lw=0.8)
            ax.quiver(X, Y, Dp[..., u], Dp[..., w], angles="xy", scale_units="xy", scale=1 / (mag * 1e-3), width=0.003)
            scale = f"magnified ×{mag:g}" if mag > 1 else "at true scale"
            ax.set_title(f"error field in the {'xyz'[u]}{'xyz'[w]} plane [mm]\narrows and deformed grid (red) {scale}")
            for c, axc in zip(range(3), (axs[0, 1], axs[1, 0], axs[1, 1])):
                m = axc.pcolormesh(X, Y, Dp[..., c], shading="gouraud", cmap="RdBu_r",
                                   vmin=-np.abs(Dp[..., c]).max(), vmax=np.abs(Dp[..., c]).max())
                fig.colorbar(m, cax=axc.inset_axes([1.03, 0.0, 0.04, 1.0]), label=f"Δ{'xyz'[c]} [µm]")
                axc.set_title(f"Δ{'xyz'[c]} [µm]: {Dp[..., c].min():+.2f} … {Dp[..., c].max():+.2f}")
            for a in axs.flat:
                a.set_aspect("equal" if to_scale else "auto")
                a.set_xlabel(f"workpiece {'xyz'[u]} [mm]")
                a.set_ylabel(f"workpiece {'xyz'[w]} [mm]")
            others = [k for k in range(len(sweep)) if k not in (i, j)]
            at = ", ".join(_at(sweep[k], values[k][shape[k] // 2], rotary[sweep[k]]) for k in others)
            fig.suptitle(f"{chain.name}: volumetric error, axes {sweep[i]}/{sweep[j]} swept" + (f" at {at}" if at else "")
                         + "".join(f"\n{n}" for n in (note, scale_note) if n))
        with out.write(name.name, binary=True) as stream:
            fig.savefig(stream, format="png", dpi=90)
    return files
