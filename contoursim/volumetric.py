"""The ``contoursim volumetric MACHINE`` job: volumetric error over the workspace.

Evaluates the machine's volumetric error (actual minus ideal tool tip and
tool axis, in workpiece coordinates) on a grid of axis positions spanning the
travels, prints the worst errors per component and plots the error field:
magnified arrows and colour maps, one figure per plane of linear axes.
"""

from itertools import combinations

import numpy as np

from .exceptions import ConfigError
from .output import output_dir
from .machine import load_machine
from .multibody import MachineChain
from .plotting import magnification_for

__all__ = ["volumetric_grid", "volumetric_report"]


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
        ``{axis: (min, max)}`` [mm or rad]; default the axes' travels.
    fixed : dict, optional
        ``{axis: position}`` for the other axes [mm or rad]; default 0.

    Returns
    -------
    q : ndarray, shape (points**len(sweep), n_axes)
        Axis positions [mm, rad], the swept axes varying as ``np.meshgrid(..., indexing="ij")``.
    axes : tuple of ndarray
        The grid values of each swept axis.
    """
    sweep = _swept(chain, sweep)
    unknown = set(sweep) - set(chain.axes)
    if unknown or not sweep:
        raise ValueError(f"sweep must name some of the axes {list(chain.axes)}, got {sweep}")
    points = int(points)
    if points < 2:
        raise ValueError(f"points must be at least 2, got {points}")
    travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
    ranges = dict(ranges or {})
    values = []
    for a in sweep:
        lohi = ranges.get(a, travel[a])
        if lohi is None:
            raise ValueError(f"axis {a!r} has no travel: give its range")
        values.append(np.linspace(lohi[0], lohi[1], points))
    fixed = dict(fixed or {})
    mesh = np.meshgrid(*values, indexing="ij")
    q = np.zeros((mesh[0].size, len(chain.axes)))
    for a, v in fixed.items():
        if a not in chain.axes:
            raise ValueError(f"fixed: unknown axis {a!r}")
        q[:, chain.axes.index(a)] = v
    for a, m in zip(sweep, mesh):
        q[:, chain.axes.index(a)] = m.ravel()
    return q, tuple(values)


def _swept(chain, sweep):
    """The axes to sweep: `sweep`, or by default the linear axes."""
    return [a for a, rot in zip(chain.axes, chain.rotary_axes) if not rot] if sweep is None else list(sweep)


def volumetric_report(machine, out_dir=None, grid=11, sweep=None, ranges=None, fixed=None, time=0.0):
    """Worst volumetric errors over the workspace, and error-field plots.

    Parameters
    ----------
    machine : str, Path or MachineChain
        A machine preset name or machine file with a geometric half
        (``[[body]]``), or the chain itself.
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

    Returns
    -------
    str
        The summary table.

    Raises
    ------
    ConfigError
        The machine file is bad or has no geometric half, or `out_dir` cannot be used.
    FileExistsError
        A plot's file exists in `out_dir` and contoursim did not write it.
    """
    if isinstance(machine, MachineChain):
        chain = machine
    else:
        chain = load_machine(machine).chain
        if chain is None:
            raise ConfigError("the machine has no geometric half ([[body]] tables): nothing to map", str(machine))
    q, values = volumetric_grid(chain, sweep, grid, ranges, fixed)
    sweep = _swept(chain, sweep)
    rotary = dict(zip(chain.axes, chain.rotary_axes))
    t = np.full(q.shape[0], float(time))
    dp, dv = chain.volumetric_error(q, t)
    text = _summary(chain, q, dp, dv, sweep, values, float(time), rotary)
    if out_dir is not None:
        out = output_dir(out_dir)
        ideal = chain.tool_pose(q, t, ideal=True)[0]
        files = _plot(chain, q, ideal, dp, sweep, values, out)
        text += "\nplots: " + ", ".join(str(f) for f in files) + "\n"
    return text


def _fmt_q(chain, q, rotary):
    return ", ".join(f"{a}={np.rad2deg(v):.1f}°" if rotary[a] else f"{a}={v:.1f} mm" for a, v in zip(chain.axes, q))


def _summary(chain, q, dp, dv, sweep, values, time, rotary):
    lines = [
        f"volumetric error of {chain.name or 'machine'}",
        f"grid: {len(q)} points over " + ", ".join(f"{a} {_span(v, rotary[a])}" for a, v in zip(sweep, values))
        + (f", t = {time:g} s" if time else ""),
        "",
        f"{'component':20s} {'worst':>10s} {'min':>10s} {'max':>10s}  at (axis positions)",
    ]
    rows = [(f"position {c} [µm]", 1e3 * dp[:, i]) for i, c in enumerate("xyz")]
    rows.append(("position |Δ| [µm]", 1e3 * np.linalg.norm(dp, axis=1)))
    rows += [(f"tool axis {c} [µrad]", 1e6 * dv[:, i]) for i, c in enumerate("xyz")]
    for label, v in rows:
        k = int(np.argmax(np.abs(v)))
        lines.append(f"{label:20s} {v[k]:+10.3f} {v.min():+10.3f} {v.max():+10.3f}  {_fmt_q(chain, q[k], rotary)}")
    return "\n".join(lines) + "\n"


def _span(v, rot):
    lo, hi = (np.rad2deg(v[[0, -1]]) if rot else v[[0, -1]])
    return f"{lo:g}..{hi:g}{'°' if rot else ' mm'}"


def _plot(chain, q, ideal, dp, sweep, values, out):
    """One figure per pair of swept axes (middle of the others): arrows and colour maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = tuple(len(v) for v in values)
    P = ideal.reshape(shape + (3,))
    D = 1e3 * dp.reshape(shape + (3,))
    pairs = list(combinations(range(len(sweep)), 2))[:3] or [(0, None)]
    files = [out.file(f"volumetric_{sweep[i]}{'' if j is None else sweep[j]}.png") for i, j in pairs]
    for (i, j), name in zip(pairs, files):
        index = [s // 2 for s in shape]
        index[i] = slice(None)
        if j is not None:
            index[j] = slice(None)
        Pp, Dp = P[tuple(index)], D[tuple(index)]
        if j is None:
            fig, ax = plt.subplots(figsize=(7, 4), layout="constrained")
            for c in range(3):
                ax.plot(values[0], Dp[:, c], label=f"Δ{'xyz'[c]}")
            ax.set_xlabel(f"axis {sweep[0]}")
            ax.set_ylabel("volumetric error [µm]")
            ax.legend()
        else:
            spread = np.ptp(Pp.reshape(-1, 3), axis=0)
            u, w = np.argsort(spread)[::-1][:2]
            u, w = sorted((u, w))
            X, Y = Pp[..., u], Pp[..., w]
            size = max(np.ptp(X), np.ptp(Y))
            biggest = np.max(np.hypot(Dp[..., u], Dp[..., w])) * 1e-3
            mag = magnification_for(size, biggest)
            fig, axs = plt.subplots(2, 2, figsize=(11, 9), layout="constrained")
            ax = axs[0, 0]
            ax.plot(X, Y, color="0.8", lw=0.6)
            ax.plot(X.T, Y.T, color="0.8", lw=0.6)
            Xa, Ya = X + mag * 1e-3 * Dp[..., u], Y + mag * 1e-3 * Dp[..., w]
            ax.plot(Xa, Ya, color="C3", lw=0.8)
            ax.plot(Xa.T, Ya.T, color="C3", lw=0.8)
            ax.quiver(X, Y, Dp[..., u], Dp[..., w], angles="xy", scale_units="xy", scale=1 / (mag * 1e-3), width=0.003)
            ax.set_aspect("equal")
            ax.set_title(f"error field, {'xyz'[u]}{'xyz'[w]} plane\narrows and deformed grid (red) magnified ×{mag:g}")
            ax.set_xlabel(f"workpiece {'xyz'[u]} [mm]")
            ax.set_ylabel(f"workpiece {'xyz'[w]} [mm]")
            for c, axc in zip(range(3), (axs[0, 1], axs[1, 0], axs[1, 1])):
                m = axc.pcolormesh(X, Y, Dp[..., c], shading="gouraud", cmap="RdBu_r",
                                   vmin=-np.abs(Dp[..., c]).max(), vmax=np.abs(Dp[..., c]).max())
                fig.colorbar(m, ax=axc, label=f"Δ{'xyz'[c]} [µm]")
                axc.set_aspect("equal")
                axc.set_title(f"Δ{'xyz'[c]}, range {Dp[..., c].min():+.2f} … {Dp[..., c].max():+.2f} µm")
                axc.set_xlabel(f"workpiece {'xyz'[u]} [mm]")
                axc.set_ylabel(f"workpiece {'xyz'[w]} [mm]")
            others = [k for k in range(len(sweep)) if k not in (i, j)]
            at = ", ".join(f"{sweep[k]} = {values[k][shape[k] // 2]:g}" for k in others)
            fig.suptitle(f"{chain.name}: volumetric error, axes {sweep[i]}/{sweep[j]}" + (f" at {at}" if at else ""))
        with out.write(name.name, binary=True) as stream:
            fig.savefig(stream, format="png", dpi=90)
        plt.close(fig)
    return files
