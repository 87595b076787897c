"""Contour error estimators side by side: accuracy against the exact contour error, and cost.

For the ISO 230-4 circle, the rounded square, the butterfly free-form curve and
the 3-D helix of trajectories/, each at 1/4, 1x and 4x its file's feed, an
actual trace is simulated with a realistic servo lag (the stepping kernel with
a P-PI cascade per axis, or with ``--servo lag`` a first-order lag per axis,
exact discrete form, time constant 1/Kp). Every estimator is then compared
with the exact contour error (:func:`contoursim.contour.exact_contour_error`,
which :func:`contoursim.estimators.exact` delegates to) over the measured
samples: for the ISO circle those whose exact foot point lies on the test
circle itself, not on its run-in or run-out arc:

    max |Δ|, rms |Δ|   error of the estimated magnitude [µm]
    rel                max |Δ| / max ε
    worst              max of |Δ| / max(1 % of ε, 1 nm): <= 1 meets the target
    ns/sample          wall time of the offline estimate over the trace

A second table sweeps the servo period (so the reference sample spacing,
feed x dt) at the high feed, with the first-order lag (the kernel rejects
servo periods too long for its velocity loop).

Run:  python benchmarks/bench_estimators.py [--servo kernel|lag] [--kp 35]
"""

import argparse
import dataclasses
import time
from importlib.resources import files

import numpy as np
from scipy.signal import lfilter

from contoursim import estimators as est
from contoursim.contour import exact_contour_error
from contoursim.feed import sample
from contoursim.kernel import run
from contoursim.pathfile import load_path_file
from contoursim.servo import AxisServo

DT = 2e-4  # servo period [s] (5 kHz)
PATHS = [
    ("ISO circle", "iso230_4_circle_ccw.toml"),
    ("rounded square", "rounded_square.toml"),
    ("butterfly", "butterfly.toml"),
    ("helix", "helix.toml"),
]
FEEDS = [("low", 0.25), ("nominal", 1.0), ("high", 4.0)]
SWEEP_DT = [2e-4, 1e-3, 4e-3]  # servo periods of the sample spacing sweep [s]
ESTIMATORS = ["linear", "circular", "three_point", "newton"]
TOL_REL, TOL_ABS = 0.01, 1e-6  # target: within 1 % or 1 nm [mm], whichever is larger


def actual_trace(traj, servo, kp, dt):
    """Tool positions following the reference: the kernel, or a first-order lag per axis."""
    if servo == "kernel":
        axis = AxisServo(mass=300.0, force_constant=900.0, kv=200.0, ti=0.01, kp=kp)
        return run([axis] * traj.dim, dt, traj.position, traj.velocity, traj.acceleration).position
    # q' = kp (r - q) with r held over each period: q[k+1] = a q[k] + (1 - a) r[k], a = exp(-kp dt)
    a = np.exp(-kp * dt)
    zi = traj.position[:1]  # lfilter's state: q[0] = zi = r[0], at rest on the start point
    return lfilter([0.0, 1.0 - a], [1.0, -a], traj.position, axis=0, zi=zi)[0]


def timed(fn, *args):
    best, result = np.inf, None
    for _ in range(2):
        start = time.perf_counter()
        result = fn(*args)
        best = min(best, time.perf_counter() - start)
    return result, best


def compare(path, settings, feed, dt, servo, kp, circle):
    """Simulate one case and score every estimator against the exact contour error.

    Returns the trace length, the largest exact error [mm], the exact
    computation's time [s] and, per estimator, (max |Δ|, rms |Δ|, worst, time).
    """
    traj = sample(path, dataclasses.replace(settings, feed=feed).plan(path), dt)
    actual = actual_trace(traj, servo, kp, dt)
    exact, t_exact = timed(exact_contour_error, traj, actual)
    m = np.array(path.roles)[path.segment_index(exact.s)] == "test" if "test" in path.roles else slice(None)
    eps = exact.magnitude[m]
    scores = {}
    for name in ESTIMATORS:
        if name == "circular":
            if circle is None:
                continue
            got, seconds = timed(est.circular, actual, *circle)
        else:
            got, seconds = timed(getattr(est, name), traj.position, actual)
        delta = np.abs(got.magnitude[m] - eps)
        worst = np.max(delta / np.maximum(TOL_REL * eps, TOL_ABS))
        scores[name] = delta.max(), np.sqrt(np.mean(delta**2)), worst, seconds
    return len(traj), eps.max(), t_exact, scores


def warm_up():
    """Compile (or load from the cache) every estimator once, outside the timings."""
    ref = np.column_stack([np.linspace(0.0, 1.0, 8), np.zeros(8)])
    for name in ("linear", "three_point", "newton"):
        getattr(est, name)(ref, ref)
    est.circular(ref, (0.0, 0.0), 1.0)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--servo", choices=["kernel", "lag"], default="kernel")
    parser.add_argument("--kp", type=float, default=35.0, help="position loop gain [1/s]")
    args = parser.parse_args()
    model = ("kernel: P-PI cascade per axis (m = 300 kg, kf = 900 N/A, kv = 200 A s/m, Ti = 10 ms)"
             if args.servo == "kernel" else "first-order lag per axis, exact discrete form, tau = 1/Kp")
    print(f"servo: {model}, Kp = {args.kp:g} 1/s, dt = {DT * 1e3:g} ms ({1 / DT:g} Hz)")
    warm_up()
    library = {label: load_path_file(files("contoursim.trajectories") / file) for label, file in PATHS}
    circles = {"ISO circle": ((0.0, 0.0), 50.0)}

    head = (f"{'path':<15} {'feed':>5} {'N':>7} {'max ε':>9}  {'estimator':<12} {'max |Δ|':>10} "
            f"{'rms |Δ|':>10} {'rel':>9} {'worst':>9} {'ns/sample':>9}")
    print(head)
    print(f"{'':<15} {'mm/min':>5} {'':>7} {'µm':>9}  {'':<12} {'µm':>10} {'µm':>10} {'':>9} {'':>9} {'':>9}")
    print("-" * len(head))
    summary = {}
    for label, (path, settings) in library.items():
        for level, factor in FEEDS:
            feed = float(np.max(settings.feed)) * factor
            n, eps_max, t_exact, scores = compare(path, settings, feed, DT, args.servo, args.kp, circles.get(label))
            print(f"{label:<15} {feed * 60:>5.0f} {n:>7} {eps_max * 1e3:>9.3f}  {'exact':<12} "
                  f"{'':>10} {'':>10} {'':>9} {'':>9} {t_exact / n * 1e9:>9.0f}")
            for name, (dmax, drms, worst, seconds) in scores.items():
                summary[label, level, name] = dmax, worst
                print(f"{'':<15} {'':>5} {'':>7} {'':>9}  {name:<12} {dmax * 1e3:>10.3g} {drms * 1e3:>10.3g} "
                      f"{dmax / eps_max:>9.2e} {worst:>9.3g} {seconds / n * 1e9:>9.0f}")

    print()
    print("targets")
    for label in library:
        worst = summary[label, "nominal", "three_point"][1]
        print(f"  three-point within 1 % or 1 nm at nominal feed, {label:<15}: worst = {worst:.3g}  "
              f"{'PASS' if worst <= 1 else 'FAIL'}")
    for label in ("ISO circle", "butterfly"):
        for level, _ in FEEDS:
            ratio = summary[label, level, "linear"][0] / max(summary[label, level, "three_point"][0], 1e-15)
            print(f"  three-point vs linear max |Δ|, {label:<10} {level:<7}: {ratio:9.3g}x  "
                  f"{'PASS' if ratio >= 10 else 'FAIL'}")

    # offline estimation of a 300,000-sample trace (the ISO circle at the low feed, cut)
    path, settings = library["ISO circle"]
    traj = sample(path, dataclasses.replace(settings, feed=settings.feed / 4).plan(path), DT)
    ref, actual = traj.position[:300_000], actual_trace(traj, args.servo, args.kp, DT)[:300_000]
    for name in ("linear", "three_point", "newton"):
        _, seconds = timed(getattr(est, name), ref, actual)
        verdict = f"  {'PASS' if seconds < 0.1 else 'FAIL'} (< 0.1 s)" if name == "three_point" else ""
        print(f"  offline {name:<11} on a {len(ref):,}-sample trace: {seconds * 1e3:6.1f} ms{verdict}")

    print()
    print("sample spacing sweep (first-order lag, high feed): max |Δ| [µm] (worst) as the servo period grows")
    print(f"{'path':<15} {'feed':>5} {'dt':>6} {'spacing':>8} {'max ε':>9}  "
          + "  ".join(f"{name:>19}" for name in ("linear", "three_point", "newton")))
    print(f"{'':<15} {'mm/min':>5} {'ms':>6} {'µm':>8} {'µm':>9}")
    for label, (path, settings) in library.items():
        feed = float(np.max(settings.feed)) * FEEDS[-1][1]
        for dt in SWEEP_DT:
            _, eps_max, _, scores = compare(path, settings, feed, dt, "lag", args.kp, None)
            cells = "  ".join(f"{scores[name][0] * 1e3:>9.3g} ({scores[name][2]:>7.3g})"
                              for name in ("linear", "three_point", "newton"))
            print(f"{label:<15} {feed * 60:>5.0f} {dt * 1e3:>6.1f} {feed * dt * 1e3:>8.1f} "
                  f"{eps_max * 1e3:>9.3f}  {cells}")


if __name__ == "__main__":
    main()
