"""How well `contoursim diagnose` names a hidden effect: two families of generated cases, run blind.

**own**: the demo mill's X, Y (and Z for the helix) servo axes at a 0.5 ms
servo period, every position gain set to X's (the mill's Y is tuned 10 %
lower on purpose: a gain mismatch of its own, which a case would hide
without naming it and which a diagnosis without the model rightly finds),
each with a travel 2–4 times the path's extent (the path anywhere in it);
a path of trajectories/ (ISO 230-4 circle CCW or CW, the
butterfly free-form curve, the 3-D helix); a "truth" that is the nominal
machine with each axis's mass, force constant and damping off by up to
±3 %, the controller exact (:func:`contoursim.diagnosis.synthetic_trace`:
the diagnosis's own kernel), one hidden catalogue effect of random size within
its typical range on a random axis (or none: a null case), measurement
noise of 0.05–0.5 µm RMS, quantisation to 0.05 µm, logged every 1 ms.

**rigid**, **two_mass**: traces from a simulator that shares no code with
contoursim (independent_truth.py beside this script: continuous-time
plants by RK4 substeps, PI velocity loops on encoder differences, Dahl or
LuGre friction, motor or scale feedback, its own interpolators, logging
decimation and jitter), each with the machine's data sheet (controller
exact, plant within ±3 %) written beside it as a machine file.

Each case is diagnosed as a user would: with the nominal model
(``--model``: the demo mill's axes, or the data sheet) and without it (the
loops identified from the trace); mode ``current`` (the independent
families) diagnoses with the data sheet the same trace with each drive's
logged current command beside the positions (``<axis>_current``), which
the fit takes as a second output. A diagnosis that ends in an error counts
as wrong. Without the model a gain mismatch on two axes counts on either
axis, as the ratio of their gains: one shared position gain is identified,
so that ratio is all the trace can tell. Printed per family and mode: the
cases answered, named right (the named effects are exactly the hidden one,
or nothing on a null case), the same over the cases whose effect adds at
least the noise level (its RMS contribution, the same truth with and
without it, its mean per axis left out, against the noise the diagnosis
estimates), the cases with a false positive (an effect named that
is not hidden), the null cases kept clean, the median error of the main
parameter and its 2σ coverage (the truth within twice the reported
uncertainty) where the hidden effect was named, the median seconds per
30 s of trace; then per effect: named right / cases, the hidden effect among those named, its
median parameter error and 2σ coverage. Progress goes to stderr.

Run:  python benchmarks/bench_diagnose.py [--cases 22] [--seed 1] [--families own,rigid,two_mass]
                                         [--modes model,current,identified]
                                         [--effects none,squareness,straightness]
      python benchmarks/bench_diagnose.py --fast      (one null case and one effect per family and mode)
"""

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import independent_truth
from contoursim.diagnosis import diagnose, synthetic_trace
from contoursim.effects import CATALOGUE, Effect, effect_kind
from contoursim.feed import sample
from contoursim.machine import Machine, load_machine
from contoursim.model import Model, load_model
from contoursim.pathfile import load_path_file
from contoursim.traces import read_trace

SERVO_PERIOD = 5e-4  # [s]
PATHS = ("iso230_4_circle_ccw", "iso230_4_circle_cw", "butterfly", "helix")
#: The parameter scored for each effect.
MAIN = {"backlash": "lost_motion_um", "coulomb_friction": "force_N", "gain_mismatch": "kp_ratio",
        "squareness": "angle_urad", "scale_error": "ppm", "cyclic_error": "amplitude_um", "straightness": "peak_um",
        "time_delay": "delay_s", "thermal_drift": "rate_um_per_min", "vibration": "freq_hz"}


def hidden_effect(name, axes, travel, rng):
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
        start, end = travel[axis]
        return Effect(name, axis, peak_um=sign * rng.uniform(2, 15), span_mm=end - start, start_mm=start, error_direction=other)
    if name == "time_delay":
        return Effect(name, axis, delay_s=rng.uniform(1e-4, 3e-3), kind=str(rng.choice(["command", "feedback"])))
    if name == "thermal_drift":
        return Effect(name, axis, rate_um_per_min=sign * rng.uniform(1, 10))
    if name == "vibration":
        return Effect(name, axis, freq_hz=rng.uniform(30, 150), damping_ratio=rng.uniform(0.01, 0.2))
    raise ValueError(name)


def cases(n, seed, effects=(None,) + CATALOGUE):
    """`n` cases cycling through `effects` (``None``: a null case), ``(effect name, seed)``.

    By default one in eleven is a null case, the others cycle through the catalogue.
    """
    rng = np.random.default_rng(seed)
    return [(effects[i % len(effects)], int(rng.integers(1 << 30))) for i in range(n)]


def travel(reference, axes, seed):
    """Each axis's travel [mm]: 2–4 times the path's extent, the path somewhere within it (its own random stream)."""
    rng = np.random.default_rng([seed, 1])
    out = {}
    for i, a in enumerate(axes):
        lo, hi = float(reference.position[:, i].min()), float(reference.position[:, i].max())
        length = max(hi - lo, 1.0) * rng.uniform(2.0, 4.0)
        start = lo - rng.uniform(0.0, 1.0) * (length - (hi - lo))
        out[a] = (start, start + length)
    return out


def own_case(mill, name, seed):
    """A case of the own family: ``(trace, nominal model, truth dict or None, effect's RMS [µm])``."""
    rng = np.random.default_rng(seed)
    path_name = PATHS[int(rng.integers(len(PATHS)))]
    path, settings = load_path_file(path_name)
    axes = ("x", "y", "z") if path.dim == 3 else ("x", "y")
    reference = sample(path, settings.plan(path), SERVO_PERIOD)
    machine = Machine({a: replace(mill.axes[a], kp=mill.axes["x"].kp) for a in axes}, SERVO_PERIOD,
                      axis_travel=travel(reference, axes, seed))
    truth = () if name is None else (hidden_effect(name, axes, machine.travel, rng),)
    if truth and truth[0].name == "backlash":  # where its axis's loop reads is the machine's, known to the diagnosis
        a = truth[0].axis
        machine = replace(machine, axes={**machine.axes, a: replace(machine.axes[a], position_feedback=truth[0].options["feedback"])})
    noise = rng.uniform(0.05, 0.5)
    trace = synthetic_trace(Model(machine, truth), reference, mismatch=0.03, noise_um=noise, quantum_um=0.05,
                            every=2, seed=seed)
    clean = [synthetic_trace(Model(machine, effects), reference, mismatch=0.03, noise_um=0.0, quantum_um=0.0, every=2,
                             seed=seed).actual for effects in (truth, ())]
    added = clean[0] - clean[1]
    added -= added.mean(axis=0)  # a constant shift is the instrument's zero: no trace shows it
    signal = 1e3 * float(np.sqrt(np.mean(np.sum(added**2, axis=1))))
    described = None if not truth else dict(name=truth[0].name, axis=truth[0].axis, parameters=truth[0].values(),
                                            options=dict(truth[0].options))
    return path_name, trace, Model(machine), described, signal


def independent_case(family, name, seed, folder, currents=False):
    """A case of an independent family: ``(path, trace, data sheet's file, truth dict or None, effect's RMS [µm])``;
    with `currents` the trace carries the drives' current commands."""
    case = independent_truth.make_case(family, name, seed, folder, currents=currents)
    return case.path, read_trace(case.csv), case.machine_file, case.truth, case.signal_um


def truth_value(truth, named):
    """The truth's main parameter in the named effect's terms (a straightness bow over the named span)."""
    key = MAIN[truth["name"]]
    value = truth["parameters"][key]
    if truth["name"] == "straightness":  # the same curvature over the named span
        value *= (named["span_mm"] / truth["parameters"]["span_mm"]) ** 2
    return value


def equivalent(truth, report, axes):
    """The truth as the report can know it: without a nominal model, on two axes, a gain mismatch only as a ratio.

    With one position gain identified for both axes, kp_ratio r on one axis and 1/r on the other are the
    same machine; the report's choice of axis is then graded in its own terms.
    """
    if truth is None or truth["name"] != "gain_mismatch" or not report["nominal_identified"] or len(axes) != 2:
        return truth
    other = next(a for a in axes if a != truth["axis"])
    if not any(e["name"] == "gain_mismatch" and e["axis"] == other for e in report["effects"]):
        return truth
    return dict(truth, axis=other, parameters=dict(truth["parameters"], kp_ratio=1.0 / truth["parameters"]["kp_ratio"]))


def grade(truth, report, named):
    """What one diagnosis got right: exact set, false positives, the main parameter's error and 2σ coverage."""
    labels = [(e["name"], e["axis"]) for e in report["effects"]]
    hidden = [] if truth is None else [(truth["name"], truth["axis"])]
    graded = dict(right=sorted(labels) == hidden, false_positive=any(label not in hidden for label in labels),
                  found=bool(hidden) and hidden[0] in labels)
    if graded["found"]:
        k = labels.index(hidden[0])
        key = MAIN[truth["name"]]
        value = truth_value(truth, named[k])
        sigma = report["effects"][k].get("uncertainty", {}).get(key)
        graded["parameter_error"] = abs(named[k][key] - value) / abs(value)
        graded["covered"] = sigma is not None and abs(named[k][key] - value) <= 2 * sigma
    return graded


def run(family, mode, name, seed, mill, folder):
    """Generate one case and diagnose it blind in `mode` ("model", "current" or "identified"); a dict of what
    happened."""
    if family == "own":
        path, trace, model, truth, signal = own_case(mill, name, seed)
    else:
        path, trace, model, truth, signal = independent_case(family, name, seed, folder, currents=mode == "current")
    case = dict(family=family, mode=mode, truth=truth, path=path, signal=signal, duration=float(trace.t[-1] - trace.t[0]),
                error=None, named=(), right=False, false_positive=False, found=False, floor=np.inf)
    start = time.perf_counter()
    try:
        given = mode != "identified"
        if given and isinstance(model, Path):  # as `contoursim diagnose --model` reads it
            model = load_model(model, check=False)
        result = diagnose(trace, model if given else None)
        report = result.to_dict()
    except Exception as exc:  # noqa: BLE001 - a diagnosis that fails is a result to count, not a reason to stop
        case["error"] = f"{type(exc).__name__}: {exc}"
    else:
        case.update(grade(equivalent(truth, report, trace.axes), report, result.effects), named=result.effects, before=report["residual_rms_before_um"],
                    after=report["residual_rms_after_um"], floor=float(np.linalg.norm(result.noise_um)))
    case["seconds"] = time.perf_counter() - start
    return case


def summary(results):
    """The ``name: value`` lines of one family and mode."""
    hidden = [c for c in results if c["truth"] is not None]
    nulls = [c for c in results if c["truth"] is None]
    visible = [c for c in hidden if c["signal"] >= c["floor"] and c["error"] is None]
    servo = [c for c in hidden if effect_kind(c["truth"]["name"]).stage != "geometry"]
    errors = [c["parameter_error"] for c in hidden if "parameter_error" in c]
    covered = [c["covered"] for c in hidden if "covered" in c]
    per_30 = [30.0 * c["seconds"] / c["duration"] for c in results]
    fraction = lambda xs: f"{np.mean(xs):.3f} ({sum(xs)} of {len(xs)})" if xs else "n/a"  # noqa: E731
    return {
        "cases": str(len(results)),
        "answered (no error)": fraction([c["error"] is None for c in results]),
        "named right": fraction([c["right"] for c in results]),
        "named right, effect above noise": fraction([c["right"] for c in visible]),
        "named right, servo effects": fraction([c["right"] for c in servo]),
        "hidden effect among those named": fraction([c["found"] for c in hidden]),
        "cases with a false positive": fraction([c["false_positive"] for c in results]),
        "null cases clean": fraction([c["right"] for c in nulls]),
        "median parameter error": f"{np.median(errors):.4f}" if errors else "n/a",
        "2σ coverage": fraction(covered),
        "median seconds per 30 s trace": f"{np.median(per_30):.1f}",
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=22, help="cases per family (default 22: two of each effect and null)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--families", default="own,rigid,two_mass")
    parser.add_argument("--modes", default="model,current,identified",
                        help="model: with the nominal model; current: with it, the trace carrying the drives' currents "
                             "(independent families); identified: without it")
    parser.add_argument("--effects", default=",".join(("none",) + CATALOGUE),
                        help="the hidden effects cycled through, 'none' for a null case (default: none and the catalogue)")
    parser.add_argument("--fast", action="store_true", help="two cases per family (a null case and a backlash)")
    args = parser.parse_args()
    families, modes = args.families.split(","), args.modes.split(",")
    effects = tuple(None if name == "none" else name for name in args.effects.split(","))
    strange = [m for m in modes if m not in ("model", "current", "identified")]
    if strange:
        parser.error(f"--modes: unknown mode {strange[0]!r}; the modes are: model, current, identified")
    unknown = [name for name in effects if name is not None and name not in CATALOGUE]
    if unknown:
        parser.error(f"--effects: unknown effect {unknown[0]!r}; the effects are: none, {', '.join(CATALOGUE)}")
    mill = load_machine("demo_mill")
    plan = cases(2, args.seed) if args.fast else cases(args.cases, args.seed, effects)
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for family in families:
            for i, (name, seed) in enumerate(plan):
                for mode in modes:
                    if family == "own" and mode == "current":
                        continue  # the own family's traces log no current
                    case = run(family, mode, name, seed, mill, Path(folder))
                    results.setdefault((family, mode), []).append(case)
                    named = ", ".join(e.label for e in case["named"]) or "nothing"
                    what = case["error"] or (f"named {named}; RMS {case['before'] or np.nan:.3f} -> {case['after'] or np.nan:.3f} µm "
                                             f"(noise {case['floor']:.3f})")  # a report's null (not finite) as nan
                    print(f"[{family}/{mode} {i + 1}/{len(plan)}] {'ok ' if case['right'] else 'BAD'} {case['path']:<20} "
                          f"hidden {case['truth']['name'] + '.' + case['truth']['axis'] if case['truth'] else 'none'}; "
                          f"{what}; effect {case['signal']:.3f} µm RMS; {case['seconds']:.1f} s", file=sys.stderr, flush=True)
    columns = list(results)
    head = [f"{f}/{m}" for f, m in columns]
    width = 34
    print(f"{'':<{width}}" + "".join(f"{h:>24}" for h in head))
    lines = {key: summary(results[key]) for key in columns}
    for row in next(iter(lines.values())):
        print(f"{row:<{width}}" + "".join(f"{lines[key][row]:>24}" for key in columns))
    print("\nper effect: named right / cases (hidden effect among those named) median parameter error, 2σ covered / found")
    for name in dict.fromkeys(effects):
        row = []
        for key in columns:
            these = [c for c in results[key] if (c["truth"] or {}).get("name") == name]
            errors = [c["parameter_error"] for c in these if "parameter_error" in c]
            fit = f" {np.median(errors):.2f} {sum(c['covered'] for c in these if 'covered' in c)}/{len(errors)}" if errors else ""
            row.append(f"{sum(c['right'] for c in these)}/{len(these)} ({sum(c['found'] for c in these)}){fit}" if these else "-")
        print(f"{name or 'none':<{width}}" + "".join(f"{r:>24}" for r in row))


if __name__ == "__main__":
    main()
