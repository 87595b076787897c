"""How well `contoursim diagnose` names a hidden effect: generated cases, run blind.

Each case: the demo mill's X, Y (and Z for the helix) servo axes at a 0.5 ms
servo period; a path of trajectories/ (ISO 230-4 circle CCW or CW, the
butterfly free-form curve, the 3-D helix); a "truth" that is the nominal
machine with masses, damping, velocity gains and the shared position gain
each off by up to ±3 % (:func:`contoursim.diagnosis.synthetic_trace`), one
hidden catalogue effect of random size within its typical range on a
random axis (or none: a null case), measurement noise of 0.05–0.5 µm RMS,
quantisation to 0.05 µm, logged every 1 ms. The diagnosis gets the trace
and the nominal machine only.

Printed: a confusion matrix (hidden effect vs first effect named), then
``name: value`` lines — accuracy (effect and axis right), also over the
cases whose effect adds at least the noise level to the trace (its RMS
contribution, from the same truth simulated with and without it, against
the noise estimated from the trace: a structural mode hardly excited by a
slow circle is below it), the false-positive
rate on null cases, the median error of the main parameter, the median
residual shrink (1 − RMS after / RMS before), the median seconds per
diagnosis and per 30 s of trace. Progress goes to stderr.

Run:  python benchmarks/bench_diagnose.py [--cases 60] [--seed 1]
"""

import argparse
import sys
import time
from collections import Counter

import numpy as np

from contoursim.diagnosis import diagnose, synthetic_trace
from contoursim.effects import CATALOGUE, Effect
from contoursim.feed import sample
from contoursim.machine import Machine, load_machine
from contoursim.model import Model
from contoursim.pathfile import load_path_file

SERVO_PERIOD = 5e-4  # [s]
PATHS = ("iso230_4_circle_ccw", "iso230_4_circle_cw", "butterfly", "helix")
#: The parameter scored for each effect.
MAIN = {"backlash": "lost_motion_um", "coulomb_friction": "force_N", "gain_mismatch": "kp_ratio",
        "squareness": "angle_urad", "scale_error": "ppm", "cyclic_error": "amplitude_um", "straightness": "peak_um",
        "time_delay": "delay_s", "thermal_drift": "rate_um_per_min", "vibration": "freq_hz"}


def hidden_effect(name, axes, span, rng):
    """One effect `name` of random size within its typical range, on a random axis of `axes`."""
    sign = rng.choice([-1.0, 1.0])
    axis = str(rng.choice(axes))
    if name == "backlash":
        return Effect(name, axis, lost_motion_um=rng.uniform(2, 20), feedback=str(rng.choice(["motor", "scale"])))
    if name == "coulomb_friction":
        return Effect(name, axis, force_N=float(np.exp(rng.uniform(np.log(5), np.log(200)))))
    if name == "gain_mismatch":
        return Effect(name, axis, kp_ratio=rng.uniform(0.7, 1.3))
    if name == "squareness":
        pair = sorted(rng.choice(axes, 2, replace=False))
        return Effect(name, "".join(pair), angle_urad=sign * rng.uniform(20, 200))
    if name == "scale_error":
        return Effect(name, axis, ppm=sign * rng.uniform(10, 100))
    if name == "cyclic_error":
        return Effect(name, axis, amplitude_um=rng.uniform(1, 5), period_mm=rng.uniform(4, 40), phase_deg=rng.uniform(0, 360))
    if name == "straightness":
        other = str(rng.choice([a for a in axes if a != axis]))
        return Effect(name, axis, peak_um=sign * rng.uniform(2, 15), span_mm=span[axis], error_direction=other)
    if name == "time_delay":
        return Effect(name, axis, delay_s=rng.uniform(1e-4, 3e-3), kind=str(rng.choice(["command", "feedback"])))
    if name == "thermal_drift":
        return Effect(name, axis, rate_um_per_min=sign * rng.uniform(1, 10))
    if name == "vibration":
        return Effect(name, axis, freq_hz=rng.uniform(30, 150), damping_ratio=rng.uniform(0.01, 0.2))
    raise ValueError(name)


def cases(n, seed):
    """`n` cases: one in six a null case, the others cycling through the catalogue."""
    rng = np.random.default_rng(seed)
    names = [None] + list(CATALOGUE)
    return [(names[i % len(names)] if i % 6 else None, PATHS[int(rng.integers(len(PATHS)))], int(rng.integers(1 << 30)))
            for i in range(n)]


def run_case(mill, name, path_name, seed):
    """Generate one case and diagnose it blind; returns a dict of what happened."""
    rng = np.random.default_rng(seed)
    path, settings = load_path_file(path_name)
    axes = ("x", "y", "z") if path.dim == 3 else ("x", "y")
    machine = Machine({a: mill.axes[a] for a in axes}, SERVO_PERIOD)
    reference = sample(path, settings.plan(path), SERVO_PERIOD)
    span = {a: float(np.ptp(reference.position[:, i])) or 1.0 for i, a in enumerate(axes)}
    truth = () if name is None else (hidden_effect(name, axes, span, rng),)
    noise = rng.uniform(0.05, 0.5)
    trace = synthetic_trace(Model(machine, truth), reference, mismatch=0.03, noise_um=noise, quantum_um=0.05,
                            every=2, seed=seed)
    clean = [synthetic_trace(Model(machine, effects), reference, mismatch=0.03, noise_um=0.0, quantum_um=0.0, every=2,
                             seed=seed).actual for effects in (truth, ())]
    signal = 1e3 * float(np.sqrt(np.mean(np.sum((clean[0] - clean[1]) ** 2, axis=1))))  # what the effect adds [µm RMS]
    start = time.perf_counter()
    result = diagnose(trace, Model(machine))
    seconds = time.perf_counter() - start
    named = result.effects[0] if result.effects else None
    report = result.to_dict()
    case = dict(truth=truth[0] if truth else None, named=named, path=path_name, noise=noise, seconds=seconds,
                duration=float(trace.t[-1] - trace.t[0]), before=report["residual_rms_before_um"],
                after=report["residual_rms_after_um"], floor=float(np.linalg.norm(result.noise_um)), all=result.effects,
                signal=signal)
    case["right"] = (named is None) if not truth else (
        named is not None and named.name == truth[0].name and named.axis == truth[0].axis)
    if truth and case["right"]:
        key = MAIN[name]
        case["error"] = abs(named[key] - truth[0][key]) / abs(truth[0][key])
    return case


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=60)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    mill = load_machine("demo_mill")
    results = []
    for i, (name, path_name, seed) in enumerate(cases(args.cases, args.seed)):
        case = run_case(mill, name, path_name, seed)
        results.append(case)
        truth = "none" if case["truth"] is None else repr(case["truth"])
        named = ", ".join(e.label for e in case["all"]) or "nothing"
        print(f"[{i + 1}/{args.cases}] {'ok ' if case['right'] else 'BAD'} {path_name:<20} hidden {truth}; named {named}; "
              f"effect {case['signal']:.3f} µm RMS; RMS {case['before']:.3f} -> {case['after']:.3f} µm "
              f"(noise {case['floor']:.3f}); {case['seconds']:.1f} s",
              file=sys.stderr, flush=True)
    labels = ["none"] + list(CATALOGUE)
    confusion = Counter((c["truth"].name if c["truth"] else "none", c["named"].name if c["named"] else "none")
                        for c in results)
    width = max(map(len, labels)) + 1
    print("hidden \\ named first".ljust(width + 2) + "".join(f"{label[:8]:>9}" for label in labels))
    for row in labels:
        if any(k[0] == row for k in confusion):
            print(f"{row:<{width + 2}}" + "".join(f"{confusion.get((row, col), 0):>9}" for col in labels))
    hidden = [c for c in results if c["truth"] is not None]
    nulls = [c for c in results if c["truth"] is None]
    errors = [c["error"] for c in hidden if "error" in c]
    shrink = [1 - c["after"] / c["before"] for c in hidden]
    seconds = [c["seconds"] for c in results]
    per_30 = [30.0 * c["seconds"] / c["duration"] for c in results]
    print(f"cases: {len(results)}")
    visible = [c for c in hidden if c["signal"] >= c["floor"]]
    print(f"accuracy: {np.mean([c['right'] for c in hidden]):.3f}")
    print(f"accuracy_effect_above_noise: {np.mean([c['right'] for c in visible]) if visible else float('nan'):.3f}")
    print(f"cases_effect_above_noise: {len(visible)} of {len(hidden)}")
    print(f"false_positive_rate_null: {np.mean([not c['right'] for c in nulls]) if nulls else float('nan'):.3f}")
    print(f"median_parameter_error: {np.median(errors) if errors else float('nan'):.4f}")
    print(f"median_residual_shrink: {np.median(shrink):.3f}")
    print(f"median_seconds_per_diagnosis: {np.median(seconds):.1f}")
    print(f"median_seconds_per_30s_trace: {np.median(per_30):.1f}")


if __name__ == "__main__":
    main()
