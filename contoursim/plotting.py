"""Plots of simulation results: magnified path error, ballbar polar plot, errors over time.

Every function draws on a Matplotlib ``Axes`` it is given (or a new figure)
and returns that ``Axes``, like :mod:`control.ctrlplot`; the errors over time
take a ``Figure`` for their three stacked axes. The magnification
factor of an exaggerated plot is always written on the plot; runs drawn side
by side share one. Lines are thinned to what the pixels can show (the data
itself, e.g. in the trace CSV, is untouched): :func:`envelope_indices` keeps
the smallest and largest sample of every pixel column, so no spike is lost.
"""

import numpy as np

from . import _validate
from ._blocks import BLOCK, blocks
from .output import output_dir

__all__ = [
    "circular_deviation", "envelope_indices", "fit_circle_center", "magnification_for", "plot_path_error", "plot_polar_deviation",
    "plot_errors_over_time", "save_figures", "plot_compared_paths", "plot_compared_contour_error",
    "plot_compared_figures", "save_comparison_figures",
]

_COLUMNS = 1200  # pixel columns a line is thinned to: more than any plot here is wide (<= 900 px)
_RUN_COLOURS = ("C3", "C0", "C2", "C4")  # runs overlaid: red first, as a single run is drawn


def _axes(ax, **subplot):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.figure(figsize=(6.4, 6.6), layout="constrained").add_subplot(**subplot)


def _round_125(x):
    """The smallest of 1, 2, 5 times a power of ten that is >= x (x > 0)."""
    decade = 10.0 ** np.floor(np.log10(x))
    return float(next(m * decade for m in (1.0, 2.0, 5.0, 10.0) if m * decade >= x * (1 - 1e-12)))


def _num(value, decimals=2):
    """`value` with `decimals` decimals, never as "-0.00"."""
    return f"{round(float(value), decimals) + 0.0:.{decimals}f}"


def magnification_for(size, error, fraction=0.08):
    """A round magnification that draws the largest error as about `fraction` of `size`.

    Parameters
    ----------
    size : float
        Extent of the drawing [mm].
    error : float
        Largest error to show [mm].
    fraction : float
        Share of `size` the magnified largest error should take at most.

    Returns
    -------
    float
        1, 2 or 5 times a power of ten, never below 1: an error already
        larger than `fraction` of `size` is drawn at true scale (1).

    Examples
    --------
    >>> magnification_for(100.0, 0.01)      # 0.01 mm drawn as ~8 mm
    500.0
    >>> magnification_for(100.0, 40.0)      # no shrinking "×0.2": true scale
    1.0
    """
    if error <= 0:
        return 1.0
    raw = fraction * size / error
    if raw < 1:
        return 1.0
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * decade <= raw) * decade)


class _Rows:
    """An (N, k) series made from a run's arrays when indexed (a block, or the samples drawn), never whole.

    Parameters
    ----------
    n : int
        Number of samples N.
    rows : callable
        ``rows(index)``: the rows `index` (a slice or an index array) of the series.
    """

    def __init__(self, n, rows):
        self._n, self._rows = n, rows

    def __len__(self):
        return self._n

    def __getitem__(self, index):
        return self._rows(index)


def envelope_indices(values, columns=_COLUMNS):
    """Indices of the samples that draw `values` as it looks at `columns` pixel columns.

    The samples are cut into `columns` equal runs; of each run the smallest
    and the largest value (of every series) are kept, with the first and
    last sample, so spikes survive and the line looks as the full data does.
    The runs are read a block of them at a time.

    Parameters
    ----------
    values : ndarray, shape (N,) or (N, k)
        One series or k series over the same samples, in drawing order (or
        an object of that length whose slices are such arrays).
    columns : int
        Number of runs (about the plot's width in pixels or more).

    Returns
    -------
    ndarray of int
        Sorted sample indices; all of them when N <= 2 columns.

    Examples
    --------
    >>> y = np.zeros(10_000); y[1234] = 5.0
    >>> i = envelope_indices(y, columns=100)
    >>> len(i) <= 202 and 1234 in i
    True
    """
    n = len(values)
    if n <= 2 * columns:
        return np.arange(n)
    size = -(-n // columns)
    whole = n // size * size
    block = size * max(1, BLOCK // size)  # whole runs
    picked = [[0, n - 1], np.arange(whole, n)]
    for lo in range(0, whole, block):
        part = np.asarray(values[lo : min(lo + block, whole)], float)
        runs = part.reshape(-1, size, part.size // len(part))
        start = np.arange(lo, lo + len(part), size)[:, None]
        picked += [start + runs.argmin(axis=1), start + runs.argmax(axis=1)]
    return np.unique(np.concatenate([np.ravel(p) for p in picked]))


def _thin_curve(points, step):
    """Indices of points along a curve, about `step` apart along it (and the last one) [same units].

    `points` is an (N, d) array, or an object of that length whose slices are
    such arrays (:class:`_Rows`); it is read a block at a time.
    """
    n = len(points)
    first = [[0]]
    travelled = 0.0  # along the curve up to the block's first point
    for part in blocks(n - 1):
        squares = np.diff(np.asarray(points[part.start : part.stop + 1]), axis=0)
        squares *= squares  # the segment lengths as np.linalg.norm computes them
        cell = np.empty(len(squares) + 1)  # the travelled distance, then the step it is in, in place
        cell[0] = travelled
        np.sqrt(squares.sum(axis=1), out=cell[1:])
        np.cumsum(cell, out=cell)  # sequential: the sums of one cumsum over the whole curve
        travelled = cell[-1]
        cell /= step
        np.floor(cell, out=cell)
        first.append(part.start + 1 + np.flatnonzero(cell[1:] > cell[:-1]))
    return np.union1d(np.concatenate(first), [n - 1])


def _magnified(result, k):
    """The path with its contour error magnified, ``foot + k·(actual − foot)`` in XY [mm], as :class:`_Rows`."""
    tool, foot = result.tool_position, result.contour.foot

    def rows(index):
        shown = tool[index, :2] - foot[index, :2]
        shown *= k
        shown += foot[index, :2]
        return shown

    return _Rows(len(tool), rows)


def _has_test(trajectory):
    """True when the path marks a test proper (primitives with role "test") to tell apart from the rest."""
    return trajectory.path is not None and "test" in trajectory.path.roles


def _shared_magnification(results):
    """One magnification for `results` drawn side by side: from the largest contour error of all."""
    size = max(float(np.ptp(r.trajectory.position[:, :2], axis=0).max()) for r in results)
    return magnification_for(size, max(float(r.contour.magnitude.max()) for r in results))


def plot_path_error(result, ax=None, magnification=None):
    """Reference path and the actual path with its contour error magnified.

    The magnified path is ``foot + k·(actual − foot)``: each actual point is
    moved away from its nearest path point, along the path's normal, by `k`
    times its contour error. Where ``k·ε`` exceeds the path's local radius of
    curvature on the inside of a bend (tight lobes), the drawn curve loops:
    the title says so, as such loops are not overshoot. The start is marked
    and an arrow gives the direction of travel; a 3-D path is drawn in XY.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
    ax : matplotlib.axes.Axes, optional
    magnification : float, optional
        Factor k [-], at least 1; chosen by :func:`magnification_for` when omitted.
    """
    ax = _axes(ax)
    traj, contour = result.trajectory, result.contour
    ref = traj.position[:, :2]
    size = float(np.ptp(ref, axis=0).max())
    k = magnification_for(size, float(contour.magnitude.max())) if magnification is None else \
        _validate.positive("magnification", magnification)
    if k < 1:
        raise ValueError(f"magnification must be at least 1 (true scale), got {k:g}")
    step = size / (2 * _COLUMNS)
    shown = _magnified(result, k)
    ir, ia = _thin_curve(ref, step), _thin_curve(shown, step)
    ax.plot(ref[ir, 0], ref[ir, 1], color="0.6", lw=1.0, label="reference")
    label = f"actual, contour error ×{k:g} along the path normal" if k > 1 else "actual (true scale)"
    ax.plot(*shown[ia].T, color="C3", lw=1.0, label=label)
    ax.plot(*ref[0], "o", color="k", ms=5, label="start")
    ahead = int(np.searchsorted(traj.s, traj.s[0] + 0.04 * size))
    if 0 < ahead < len(ref):
        ax.annotate("", xy=ref[ahead], xytext=ref[0], arrowprops=dict(arrowstyle="-|>", color="k", lw=1.0))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    largest = 1e3 * contour.magnitude[traj.measuring].max()
    title = f"Contour error ×{k:g}: max {largest:.2f} µm" if k > 1 else f"Contour error at true scale: max {largest:.2f} µm"
    if _has_test(traj):
        title += " on the test proper"
    notes = []
    if traj.dim == 3 and np.ptp(traj.position[:, 2]) > 0:
        notes.append("3-D path shown in XY (z not drawn)")
    if k > 1 and traj.path is not None:
        _, _, bend = traj.path.derivatives(contour.s[ia])  # curvature vector, towards the centre of the bend
        if np.any(k * np.einsum("ij,ij->i", result.tool_position[ia] - contour.foot[ia], bend[:, : traj.dim]) > 1):
            notes.append(f"loops: ×{k:g} error exceeds the bend radius, not overshoot")
        corners = traj.path.breaks[1:-1][traj.path.corner_angles() > 1e-6]  # arc length of sharp corners, increasing
        s_shown, gap = contour.s[ia], np.inf  # distance to the nearest corner: at - 1 or at, no (points, corners) table
        if corners.size:
            at = np.searchsorted(corners, s_shown)
            gap = np.minimum(np.abs(s_shown - corners[np.maximum(at - 1, 0)]),
                             np.abs(s_shown - corners[np.minimum(at, corners.size - 1)]))
        if np.any(gap < 5 * contour.magnitude[ia]):  # the foot switches between the two sides' normals there
            notes.append(f"near sharp corners the ×{k:g} offset turns between two normals: fans, not overshoot")
    ax.set_title(title + "".join(f"\n{n}" for n in notes), fontsize="medium")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, fontsize="small", frameon=False)
    return ax


def fit_circle_center(points):
    """Least-squares centre of points near a circle (algebraic fit), shape (2,) [mm].

    Parameters
    ----------
    points : ndarray, shape (N, 2)
        Points [mm].

    Examples
    --------
    >>> theta = np.linspace(0, 2 * np.pi, 50)
    >>> fit_circle_center(np.column_stack([3 + 2 * np.cos(theta), -1 + 2 * np.sin(theta)])).round(12)
    array([ 3., -1.])
    """
    # |p|^2 = 2 c.p + (R^2 - |c|^2) is linear in c and the constant
    basis = np.column_stack([2 * points, np.ones(len(points))])
    solution, *_ = np.linalg.lstsq(basis, (points**2).sum(axis=1), rcond=None)
    return solution[:2]


def circular_deviation(result):
    """Ballbar evaluation of a circular test over its test proper (``trajectory.measuring``).

    As ISO 230-4 and a ballbar's software do: the data-collection circle only
    (the samples whose reference lies on the test circle, so no run-in or
    overrun transient), the least-squares centre of the measured points
    removed, the circularity the range of the radial deviation about it.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
        A run on a path with a test circle (:meth:`contoursim.paths.Path.test_circle`).

    Returns
    -------
    dict
        ``theta`` [rad] and ``deviation`` |p − c| − R [µm] of the measured
        points about the least-squares centre c, the ``offset`` c − nominal
        centre [µm], ``circularity`` max − min deviation [µm], ``radius`` R
        [mm] and ``direction`` ("CCW" or "CW").
    """
    circle = result.trajectory.path.test_circle()
    points = result.tool_position[result.trajectory.measuring, :2]
    fitted = fit_circle_center(points)
    rel = points - fitted
    deviation = 1e3 * (np.hypot(rel[:, 0], rel[:, 1]) - circle.radius)
    return dict(theta=np.arctan2(rel[:, 1], rel[:, 0]), deviation=deviation, offset=1e3 * (fitted - circle.center[:2]),
                circularity=float(np.ptp(deviation)), radius=circle.radius, direction="CCW" if circle.sweep > 0 else "CW")


def plot_polar_deviation(runs, ax=None):
    """Ballbar polar plot of circular tests, runs overlaid (e.g. CW and CCW).

    Each run is evaluated over its test proper (``trajectory.measuring``: the
    data-collection circle of an ISO 230-4 test, without run-in, overruns and
    run-out) as a ballbar's software does: the least-squares centre of the
    measured points is removed (offset in the legend) and the radial axis is
    the deviation |p − c| − R [µm], zero on the dashed nominal circle. The
    circularity is the range of that deviation (max − min). The rings are a
    round number of µm apart, given in the title.

    Parameters
    ----------
    runs : SimResult or dict of str -> SimResult
        One run, or runs by name, whose path has a test circle
        (:meth:`contoursim.paths.Path.test_circle`). Runs of different
        directions are labelled by direction, others by name too.
    ax : matplotlib.axes.Axes with polar projection, optional

    Raises
    ------
    ValueError
        A run's path has no test circle.
    """
    runs = dict(runs) if isinstance(runs, dict) else {"": runs}
    results = list(runs.values())
    for r in results:
        if r.trajectory.path is None or r.trajectory.path.test_circle() is None:
            raise ValueError("a polar plot needs runs on a path with a full test circle (role 'test')")
    ax = _axes(ax, projection="polar")
    tests = [circular_deviation(r) for r in results]
    span = max(max(float(np.abs(test["deviation"]).max()) for test in tests), 1e-3)
    division = _round_125(span / 2)  # two rings each side of zero hold every deviation
    ax.plot(np.linspace(0, 2 * np.pi, 361), np.zeros(361), "k--", lw=0.8, label="nominal radius")
    directions = [test["direction"] for test in tests]
    by_direction = len(set(directions)) == len(tests)
    for i, (name, test) in enumerate(zip(runs, tests)):
        keep = envelope_indices(test["deviation"])
        label = test["direction"] if by_direction else f"{name} ({test['direction']})"
        ax.plot(test["theta"][keep], test["deviation"][keep], color=_RUN_COLOURS[i % len(_RUN_COLOURS)], lw=1.0,
                label=f"{label}: circularity {test['circularity']:.2f} µm\n"
                      f"centre offset ({_num(test['offset'][0])}, {_num(test['offset'][1])}) µm removed")
    ax.set_rorigin(-5 * division)
    ax.set_ylim(-2 * division, 2 * division)
    ax.set_yticks(division * np.arange(-2, 3))
    ax.set_yticklabels([f"{v:g}" for v in division * np.arange(-2, 3)], fontsize="small", color="0.4")
    ax.set_rlabel_position(67.5)
    ax.grid(True, color="0.85", lw=0.6)
    for spine in ax.spines.values():  # no solid circle that could be read as a reference
        spine.set_edgecolor("none")  # (the inner one is made visible again at each draw)
    first = results[0]
    feeds = sorted({f"{60 * r.trajectory.feed:.4g}" for r in results})
    radii = sorted({f"{test['radius']:g}" for test in tests})
    ax.set_title(
        f"{first.machine.name or 'machine'}: circular test R = {', '.join(radii)} mm, F = {', '.join(feeds)} mm/min\n"
        f"{' and '.join(dict.fromkeys(directions))}; radial deviation, {division:g} µm/div",
        fontsize="medium",
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.04), fontsize="small", frameon=False)
    return ax


def plot_errors_over_time(result, fig=None):
    """Signed contour error, per-axis following error and motor current over time.

    What a servo-tuning tool shows, on linear axes: the signed in-plane
    contour error [µm] (positive to the left of travel; for a 3-D path also
    the part out of the path's plane), each servo axis's
    following error (command − actual position) [µm] and motor current
    command [A]. The test proper is shaded.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
    fig : matplotlib.figure.Figure, optional
        Where to draw three stacked axes; a new figure when omitted.

    Returns
    -------
    ndarray of matplotlib.axes.Axes, shape (3,)
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(8.0, 7.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    t = result.trajectory.t
    response, columns, error = result.servo_response, result.machine.servo_columns, result.contour
    following = _Rows(len(t), lambda i: (np.take(result.axis_command[i], columns, axis=1) - response.position[i]) * 1e3)
    names = list(result.machine.axes)
    contour, labels = _Rows(len(t), lambda i: 1e3 * error.normal[i][:, None]), ["contour error"]
    if result.trajectory.dim == 3:  # a 3-D path: the part out of the path's plane too
        contour = _Rows(len(t), lambda i: 1e3 * np.column_stack([error.normal[i], error.out_of_plane[i]]))
        labels = ["in plane", "out of plane"]
    series = [  # [µm]; the errors made block by block and at the samples drawn, not whole
        (axes[0], contour, labels, "contour error [µm]"),
        (axes[1], following, names, "following error [µm]"),
        (axes[2], response.current, names, "motor current [A]"),
    ]
    measuring = result.trajectory.measuring
    test = t[np.argmax(measuring)], t[len(measuring) - 1 - np.argmax(measuring[::-1])]  # its first and last sample
    for ax, values, labels, ylabel in series:
        keep = envelope_indices(values)
        drawn = values[keep]
        for j, label in enumerate(labels):
            ax.plot(t[keep], drawn[:, j], lw=0.9, label=label, color="C3" if ax is axes[0] and j == 0 else f"C{j}")
        if _has_test(result.trajectory):
            ax.axvspan(*test, color="0.93", zorder=0, label="test proper")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    axes[0].set_title("Contour error (signed, + left of travel), following error and current", fontsize="medium")
    axes[-1].set_xlabel("t [s]")
    return axes


def save_figures(runs, out_dir, name):
    """Write the standard plots of runs shown side by side as PNG files into `out_dir`.

    Per run ``<run>_path.png`` (:func:`plot_path_error`, one magnification
    for all `runs`) and ``<run>_errors.png`` (:func:`plot_errors_over_time`);
    when the runs are circular tests, one ``<name>_polar.png`` with all of
    them overlaid (:func:`plot_polar_deviation`).

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
        The runs, by file name stem.
    out_dir : str, pathlib.Path or contoursim.output.OutputDir
        The output folder (see :func:`contoursim.output.output_dir`): created if
        missing; a file there that contoursim did not write is never replaced.
    name : str
        File name stem of the polar plot.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    FileExistsError
        A plot's file exists and contoursim did not write it.
    """
    results = list(runs.values())
    k = _shared_magnification(results)
    # (file, size [in], margins, drawing): fixed margins that leave room for the legends, no layout search
    path_margins = dict(left=0.12, right=0.96, top=0.90, bottom=0.16)
    drawings = [(f"{run}_path.png", (6.4, 6.8), path_margins, lambda fig, r=r: plot_path_error(r, fig.add_subplot(), k))
                for run, r in runs.items()]
    errors_margins = dict(left=0.1, right=0.84, top=0.95, bottom=0.07, hspace=0.12)
    drawings += [(f"{run}_errors.png", (8.0, 7.5), errors_margins, lambda fig, r=r: plot_errors_over_time(r, fig))
                 for run, r in runs.items()]
    if all(r.trajectory.path is not None and r.trajectory.path.test_circle() is not None for r in results):
        drawings.append((f"{name}_polar.png", (7.0, 7.6), dict(left=0.08, right=0.92, top=0.88, bottom=0.2),
                         lambda fig: plot_polar_deviation(runs, fig.add_subplot(projection="polar"))))
    return _draw(drawings, out_dir)


def _draw(drawings, out_dir):
    """Draw and write ``(file, size [in], margins, drawing)`` PNGs; all refused before any is drawn."""
    from matplotlib.figure import Figure

    out_dir = output_dir(out_dir)
    files = [out_dir.file(file) for file, *_ in drawings]
    for file, (_, size, margins, draw) in zip(files, drawings):
        fig = Figure(figsize=size)
        fig.subplots_adjust(**margins)
        draw(fig)
        with out_dir.write(file.name, binary=True) as stream:
            # zlib level 3, not PIL's 6: the same pixels, 5 ms less per figure, files 1-10 % larger
            fig.savefig(stream, format="png", dpi=110, pil_kwargs={"compress_level": 3})
    return files


# ---------------------------------------------------------------------------------------------
# Strategies compared (contoursim compare)


def plot_compared_paths(runs, ax=None, magnification=None):
    """The actual paths of several runs (strategies) on one reference, contour errors magnified alike.

    Each run is drawn as in :func:`plot_path_error` (``foot + k·(actual − foot)``)
    with one factor k for all, chosen from the largest contour error of all
    runs: a run whose error is orders of magnitude smaller lies on the
    reference at that scale, which is the comparison.

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
        Runs on the same reference, by name.
    ax : matplotlib.axes.Axes, optional
    magnification : float, optional
        Factor k [-], at least 1.

    Returns
    -------
    matplotlib.axes.Axes
    """
    ax = _axes(ax)
    results = list(runs.values())
    first = results[0]
    ref = first.trajectory.position[:, :2]
    size = float(np.ptp(ref, axis=0).max())
    k = _shared_magnification(results) if magnification is None else _validate.positive("magnification", magnification)
    step = size / (2 * _COLUMNS)
    ir = _thin_curve(ref, step)
    ax.plot(ref[ir, 0], ref[ir, 1], color="0.6", lw=2.0, label="reference")
    for i, (name, result) in enumerate(runs.items()):
        shown = _magnified(result, k)
        ia = _thin_curve(shown, step)
        largest = 1e3 * result.contour.magnitude[result.trajectory.measuring].max()
        ax.plot(*shown[ia].T, color=f"C{i}", lw=0.9, label=f"{name} (max {largest:.3g} µm)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    scale = f"×{k:g} along the path normal" if k > 1 else "at true scale"
    ax.set_title(f"Contour error of each strategy, {scale} (one factor for all)", fontsize="medium")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize="small", frameon=False)
    return ax


def plot_compared_contour_error(runs, ax=None):
    """Contour error magnitude over time of several runs, on a log scale [µm].

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
    ax : matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    ax = _axes(ax)
    for i, (name, result) in enumerate(runs.items()):
        t, error = result.trajectory.t, 1e3 * result.contour.magnitude
        keep = envelope_indices(error)
        ax.plot(t[keep], np.maximum(error[keep], 1e-6), lw=0.8, color=f"C{i}", label=name)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("contour error [µm] (log)")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Contour error over time", fontsize="medium")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    return ax


def plot_compared_figures(figures, fig=None):
    """Bar chart of a comparison's table: errors [µm] on a log scale, and the peak current [A].

    Parameters
    ----------
    figures : dict of str -> dict
        Strategy name -> :attr:`contoursim.comparison.Comparison.figures` entry.
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    ndarray of matplotlib.axes.Axes, shape (2,)
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(9.0, 6.5), layout="constrained")
    errors_ax, current_ax = fig.subplots(2, 1, height_ratios=(2, 1))
    names = list(figures)
    x = np.arange(len(names))
    keys = (("contour_max_um", "contour max"), ("contour_rms_um", "contour RMS"),
            ("tracking_max_um", "tracking max"), ("tracking_rms_um", "tracking RMS"))  # fmt: skip
    width = 0.8 / len(keys)
    for j, (key, label) in enumerate(keys):
        values = [max(figures[n][key], 1e-6) for n in names]
        errors_ax.bar(x + (j - (len(keys) - 1) / 2) * width, values, width, label=label, color=f"C{j}")
    errors_ax.set_yscale("log")
    errors_ax.set_ylabel("error [µm] (log)")
    errors_ax.set_xticks(x, names, rotation=12)
    errors_ax.grid(True, axis="y", which="both", alpha=0.3)
    errors_ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    errors_ax.set_title("Errors over the test proper and peak current, by strategy", fontsize="medium")
    currents = [figures[n]["peak_current_A"] for n in names]
    hatches = ["//" if figures[n]["saturated"] else "" for n in names]
    current_ax.bar(x, currents, 0.5, color="0.55", hatch=hatches)
    current_ax.set_ylabel("peak current [A]")
    current_ax.set_xticks(x, names, rotation=12)
    current_ax.grid(True, axis="y", alpha=0.3)
    current_ax.set_title("Peak current command (hatched: the amplifier saturated)", fontsize="medium")
    return np.array([errors_ax, current_ax])


def save_comparison_figures(comparison, out_dir, name):
    """Write ``<name>_compare_path.png``, ``<name>_compare_contour.png`` and ``<name>_compare_table.png``.

    Parameters
    ----------
    comparison : contoursim.comparison.Comparison
    out_dir : str, pathlib.Path or contoursim.output.OutputDir
        As for :func:`save_figures`.
    name : str
        File name stem.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    runs = comparison.runs
    drawings = [
        (f"{name}_compare_path.png", (7.0, 8.0), dict(left=0.12, right=0.96, top=0.93, bottom=0.2),
         lambda fig: plot_compared_paths(runs, fig.add_subplot())),
        (f"{name}_compare_contour.png", (9.0, 4.8), dict(left=0.09, right=0.78, top=0.92, bottom=0.11),
         lambda fig: plot_compared_contour_error(runs, fig.add_subplot())),
        (f"{name}_compare_table.png", (9.5, 6.5), dict(left=0.08, right=0.8, top=0.94, bottom=0.07, hspace=0.3),
         lambda fig: plot_compared_figures(comparison.figures, fig)),
    ]  # fmt: skip
    return _draw(drawings, out_dir)
