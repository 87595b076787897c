"""Plots of a simulation result: magnified path error, ballbar polar plot, errors over time.

Every function draws on a Matplotlib ``Axes`` it is given (or a new figure)
and returns that ``Axes``, like :mod:`control.ctrlplot`. The magnification
factor of an exaggerated plot is always written on the plot.
"""

import numpy as np

from .output import output_dir

__all__ = ["fit_circle_center", "magnification_for", "plot_path_error", "plot_polar_deviation", "plot_errors_over_time", "save_figures"]


def _axes(ax, **subplot):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.figure(figsize=(6.4, 6.0)).add_subplot(**subplot)


def magnification_for(size, error, fraction=0.08):
    """A round magnification that draws the largest error as `fraction` of `size`.

    Parameters
    ----------
    size : float
        Extent of the path [mm].
    error : float
        Largest error to show [mm].
    fraction : float
        Share of `size` the magnified largest error should take.

    Returns
    -------
    float
        1, 2 or 5 times a power of ten; 1 when `error` is zero.

    Examples
    --------
    >>> magnification_for(100.0, 0.01)      # 0.01 mm drawn as ~8 mm
    500.0
    """
    if error <= 0:
        return 1.0
    raw = fraction * size / error
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * decade <= raw) * decade)


def plot_path_error(result, ax=None, magnification=None):
    """Reference path and the actual path with its contour error magnified.

    The magnified path is ``foot + k·(actual − foot)``: each actual point is
    moved away from its nearest path point by `k` times its contour error.

    Parameters
    ----------
    result : contoursim.simulate.SimResult
    ax : matplotlib.axes.Axes, optional
    magnification : float, optional
        Factor k [-]; chosen by :func:`magnification_for` when omitted.
    """
    ax = _axes(ax)
    ref = result.trajectory.position
    foot = result.contour.foot
    size = float(np.ptp(ref[:, :2], axis=0).max())
    k = magnification or magnification_for(size, float(result.contour.magnitude.max()))
    shown = foot + k * (result.tool_position - foot)
    ax.plot(ref[:, 0], ref[:, 1], color="0.6", lw=1.0, label="reference")
    ax.plot(shown[:, 0], shown[:, 1], color="C3", lw=1.0, label=f"actual, contour error ×{k:g}")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"Contour error magnified ×{k:g} (max {1e3 * result.contour.magnitude.max():.2f} µm)")
    ax.legend(loc="upper right", fontsize="small")
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


def plot_polar_deviation(result, center, radius, ax=None):
    """Ballbar-style polar plot of the radial deviation over the test circle.

    Only the samples whose nearest path point lies on the test proper (the
    primitives with role ``"test"``, e.g. the full circle of an ISO 230-4
    test without its run-in and run-out arcs) are shown. As a ballbar's
    software does, the centre offset is removed first (the
    least-squares centre of the measured circle, :func:`fit_circle_center`)
    and given in the title; the radial axis is the deviation |p − c| − R [µm]
    with its zero on the dashed circle.

    Parameters
    ----------
    result : contoursim.simulate.SimResult
    center : array_like, shape (2,)
        Nominal circle centre [mm].
    radius : float
        Nominal radius R [mm].
    ax : matplotlib.axes.Axes with polar projection, optional
    """
    from matplotlib.ticker import MaxNLocator

    ax = _axes(ax, projection="polar")
    path = result.trajectory.path
    on_test = np.asarray(path.roles)[path.segment_index(result.contour.s)] == "test"
    points = result.tool_position[on_test if on_test.any() else slice(None), :2]
    fitted = fit_circle_center(points)
    offset = 1e3 * (fitted - np.asarray(center, float))
    rel = points - fitted
    theta = np.arctan2(rel[:, 1], rel[:, 0])
    dev = 1e3 * (np.hypot(rel[:, 0], rel[:, 1]) - radius)
    span = max(float(np.abs(dev).max()), 1e-3)
    ax.plot(theta, dev, color="C3", lw=1.0)
    ax.plot(np.linspace(0, 2 * np.pi, 361), np.zeros(361), "k--", lw=0.8)
    ax.set_rorigin(-2.5 * span)
    ax.set_ylim(-1.2 * span, 1.2 * span)
    ax.yaxis.set_major_locator(MaxNLocator(4, symmetric=True))
    ax.set_rlabel_position(67.5)
    ax.set_title(
        f"Radial deviation from R = {radius:g} mm [µm], dashed: zero\n"
        f"min {dev.min():.2f} µm, max {dev.max():.2f} µm; "
        f"centre offset ({offset[0]:.2f}, {offset[1]:.2f}) µm removed",
        fontsize="medium",
    )
    return ax


def plot_errors_over_time(result, ax=None):
    """Tracking error |e| and contour error ε over time [µm], on a log scale.

    Parameters
    ----------
    result : contoursim.simulate.SimResult
    ax : matplotlib.axes.Axes, optional
    """
    ax = _axes(ax)
    t = result.trajectory.t
    ax.plot(t, 1e3 * np.linalg.norm(result.tracking_error, axis=1), label="tracking error |e|")
    ax.plot(t, 1e3 * result.contour.magnitude, label="contour error ε")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("error [µm]")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.set_title("Tracking vs contour error")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return ax


def save_figures(result, out_dir, name, circle=None):
    """Write the standard plots of `result` as PNG files into `out_dir`.

    Parameters
    ----------
    result : contoursim.simulate.SimResult
    out_dir : str, pathlib.Path or contoursim.output.OutputDir
        The output folder (see :func:`contoursim.output.output_dir`): created if
        missing; a file there that contoursim did not write is never replaced.
    name : str
        File name stem.
    circle : tuple (center, radius), optional
        When given, the polar radial-deviation plot is drawn too.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    FileExistsError
        A plot's file exists and contoursim did not write it.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawings = [("path", plot_path_error, {}), ("errors", plot_errors_over_time, {})]
    if circle is not None:
        drawings.append(("polar", plot_polar_deviation, dict(center=circle[0], radius=circle[1])))
    out_dir = output_dir(out_dir)
    files = [out_dir.file(f"{name}_{kind}.png") for kind, _, _ in drawings]  # all refused before any is drawn
    for file, (kind, draw, kwargs) in zip(files, drawings):
        fig = plt.figure(figsize=(6.4, 6.0) if kind != "errors" else (8.0, 4.0))
        draw(result, ax=fig.add_subplot(projection="polar" if kind == "polar" else None), **kwargs)
        fig.tight_layout()
        with out_dir.write(file.name, binary=True) as stream:
            fig.savefig(stream, format="png", dpi=110)
        plt.close(fig)
    return files
