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
30 s of trace (each case's seconds scaled to 30 s of its trace; how many
simulations its fits take does not grow with a trace's length, so a 3-s
trace scaled so overstates what 30 s take: ``--laps N`` runs each
independent path N times, measuring it on traces as long); then per effect: named right / cases, the hidden effect among those named, its
median parameter error and 2σ coverage. Progress goes to stderr.

``--effects a+b`` hides effects a and b together in each of its cases (an
effect twice, ``coulomb_friction+coulomb_friction``: on both axes), as a
machine has more than one thing wrong: named right is then both and nothing
else, "hidden effect among those named" both, and each one named is graded
on its main parameter. One effect a case by default.

Run:  python benchmarks/bench_diagnose.py [--cases 22] [--seed 1] [--families own,rigid,two_mass]
                                         [--modes model,current,identified]
                                         [--effects none,squareness,straightness]
                                         [--effects coulomb_friction+coulomb_friction,backlash+squareness]
      python benchmarks/bench_diagnose.py --fast      (one null case and one effect per family and mode)
      python benchmarks/bench_diagnose.py --families rigid,two_mass --modes identified --laps 6   (30-s traces)
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


def cases(n, seed, effects=((),) + tuple((name,) for name in CATALOGUE)):
    """`n` cases cycling through `effects` (each the names hidden together; empty: a null case), ``(names, seed)``.

    By default one in eleven is a null case, the others cycle through the catalogue one effect a case.
    """
    rng = np.random.default_rng(seed)
    return [(tuple(effects[i % len(effects)]), int(rng.integers(1 << 30))) for i in range(n)]


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


def own_case(mill, names, seed):
    """A case of the own family: ``(path, trace, nominal model, truths, the effects' RMS [µm], each axis's velocity
    loop gain Kf·kv [N·s/m])``, one truth dict for each of the effects `names` (an effect named twice: on two axes);
    the gain the nominal model's, the trace's force constant drawn within 3 % of it."""
    rng = np.random.default_rng(seed)
    path_name = PATHS[int(rng.integers(len(PATHS)))]
    path, settings = load_path_file(path_name)
    axes = ("x", "y", "z") if path.dim == 3 else ("x", "y")
    reference = sample(path, settings.plan(path), SERVO_PERIOD)
    machine = Machine({a: replace(mill.axes[a], kp=mill.axes["x"].kp) for a in axes}, SERVO_PERIOD,
                      axis_travel=travel(reference, axes, seed))
    truth = []
    for name in names:
        taken = {e.axis for e in truth if e.name == name}  # named twice: another axis (drawn again)
        places = len(axes) * (len(axes) - 1) // 2 if name == "squareness" else len(axes)  # pairs of axes, or axes
        if len(taken) == places:
            raise ValueError(f"{name} is hidden more times than the path's axes {''.join(axes)} have places for it")
        effect = hidden_effect(name, axes, machine.travel, rng)
        while effect.axis in taken:
            effect = hidden_effect(name, axes, machine.travel, rng)
        truth.append(effect)
    for effect in (e for e in truth if e.name == "backlash"):  # where its axis's loop reads is the machine's, known
        a = effect.axis
        machine = replace(machine, axes={**machine.axes, a: replace(machine.axes[a], position_feedback=effect.options["feedback"])})
    noise = rng.uniform(0.05, 0.5)
    trace = synthetic_trace(Model(machine, truth), reference, mismatch=0.03, noise_um=noise, quantum_um=0.05,
                            every=2, seed=seed)
    clean = [synthetic_trace(Model(machine, effects), reference, mismatch=0.03, noise_um=0.0, quantum_um=0.0, every=2,
                             seed=seed).actual for effects in (truth, ())]
    added = clean[0] - clean[1]
    added -= added.mean(axis=0)  # a constant shift is the instrument's zero: no trace shows it
    signal = 1e3 * float(np.sqrt(np.mean(np.sum(added**2, axis=1))))
    described = tuple(dict(name=e.name, axis=e.axis, parameters=e.values(), options=dict(e.options)) for e in truth)
    return path_name, trace, Model(machine), described, signal, {a: _velocity_gain(machine.axes[a]) for a in axes}


def independent_case(family, names, seed, folder, currents=False, laps=1):
    """A case of an independent family: ``(path, trace, data sheet's file, truths, the effects' RMS [µm], each axis's
    true velocity loop gain Kf·kv [N·s/m])``; with `currents` the trace carries the drives' current commands; its
    path run `laps` times."""
    case = independent_truth.make_case(family, names, seed, folder, currents=currents, laps=laps)
    gains = case.notes["velocity_gain_N_s_per_m"]
    return case.path, read_trace(case.csv), case.machine_file, case.truths, case.signal_um, gains


def truth_value(truth, named):
    """The truth's main parameter in the named effect's terms (a straightness bow over the named span)."""
    key = MAIN[truth["name"]]
    value = truth["parameters"][key]
    if truth["name"] == "straightness":  # the same curvature over the named span
        value *= (named["span_mm"] / truth["parameters"]["span_mm"]) ** 2
    return value


def equivalent(truths, report, axes, gains, machine):
    """The truths as the report can know them: without a nominal model, on two axes, a gain mismatch only as a ratio,
    and a friction's force as the identified loops see it (their mass and force constant assumed).

    With one position gain identified for both axes, kp_ratio r on one axis and 1/r on the other are the
    same machine; the report's choice of axis is then graded in its own terms. A friction force F is what the
    velocity loop, of gain Kf·kv (`gains`, the truth's), sees as a speed error F / (Kf·kv) it integrates away: on
    the identified `machine`, whose mass and force constant are assumed, the same speed error is the force the
    report can know.
    """
    return tuple(_equivalent(truth, report, axes, gains, machine) for truth in truths)


def _velocity_gain(axis):
    """An axis servo's velocity loop gain Kf·kv [N·s/m]."""
    return axis.force_constant * axis.kv


def _equivalent(truth, report, axes, gains, machine):
    """:func:`equivalent` of one truth."""
    if truth["name"] == "coulomb_friction" and report["nominal_identified"]:
        a = truth["axis"]
        force = truth["parameters"]["force_N"] * _velocity_gain(machine.axes[a]) / gains[a]
        return dict(truth, parameters=dict(truth["parameters"], force_N=force))
    if truth["name"] != "gain_mismatch" or not report["nominal_identified"] or len(axes) != 2:
        return truth
    other = next(a for a in axes if a != truth["axis"])
    if not any(e["name"] == "gain_mismatch" and e["axis"] == other for e in report["effects"]):
        return truth
    return dict(truth, axis=other, parameters=dict(truth["parameters"], kp_ratio=1.0 / truth["parameters"]["kp_ratio"]))


def grade(truths, report, named):
    """What one diagnosis got right: exact set, false positives, all hidden effects among those named, and of each
    hidden effect named its main parameter's error and 2σ coverage (lists, in the order of `truths`)."""
    labels = [(e["name"], e["axis"]) for e in report["effects"]]
    hidden = [(truth["name"], truth["axis"]) for truth in truths]
    graded = dict(right=sorted(labels) == sorted(hidden), false_positive=any(label not in hidden for label in labels),
                  found=bool(hidden) and all(h in labels for h in hidden), parameter_errors=[], covered=[])
    for truth, label in zip(truths, hidden):
        if label in labels:
            k = labels.index(label)
            key = MAIN[truth["name"]]
            value = truth_value(truth, named[k])
            sigma = report["effects"][k].get("uncertainty", {}).get(key)
            graded["parameter_errors"].append(abs(named[k][key] - value) / abs(value))
            graded["covered"].append(sigma is not None and abs(named[k][key] - value) <= 2 * sigma)
    return graded


def run(family, mode, names, seed, mill, folder, laps=1):
    """Generate one case (an independent one's path run `laps` times) and diagnose it blind in `mode` ("model",
    "current" or "identified"); a dict of what happened."""
    if family == "own":
        path, trace, model, truths, signal, gains = own_case(mill, names, seed)
    else:
        path, trace, model, truths, signal, gains = independent_case(family, names, seed, folder,
                                                                      currents=mode == "current", laps=laps)
    case = dict(family=family, mode=mode, truths=truths, path=path, signal=signal, duration=float(trace.t[-1] - trace.t[0]),
                error=None, named=(), right=False, false_positive=False, found=False, parameter_errors=[], covered=[],
                floor=np.inf)
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
        truths = equivalent(truths, report, trace.axes, gains, result.refitted.machine)  # the effects fitted on it
        case.update(grade(truths, report, result.effects), named=result.effects, before=report["residual_rms_before_um"],
                    after=report["residual_rms_after_um"], floor=float(np.linalg.norm(result.noise_um)))
    case["seconds"] = time.perf_counter() - start
    return case


def summary(results):
    """The ``name: value`` lines of one family and mode."""
    hidden = [c for c in results if c["truths"]]
    nulls = [c for c in results if not c["truths"]]
    visible = [c for c in hidden if c["signal"] >= c["floor"] and c["error"] is None]
    servo = [c for c in hidden if all(effect_kind(t["name"]).stage != "geometry" for t in c["truths"])]
    errors = [e for c in hidden for e in c["parameter_errors"]]
    covered = [x for c in hidden for x in c["covered"]]
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
                        help="the hidden effects cycled through, 'none' for a null case, 'a+b' for effects a and b hidden "
                             "together (an effect twice: on two axes) (default: none and the catalogue)")
    parser.add_argument("--fast", action="store_true", help="two cases per family (a null case and a backlash)")
    parser.add_argument("--laps", type=int, default=1,
                        help="run each independent case's path this many times (traces about as many times as long: "
                             "the seconds a diagnosis of a 30-s trace takes, measured on traces that long; "
                             "independent families only)")
    args = parser.parse_args()
    families, modes = args.families.split(","), args.modes.split(",")
    effects = tuple(() if entry == "none" else tuple(entry.split("+")) for entry in args.effects.split(","))
    strange = [m for m in modes if m not in ("model", "current", "identified")]
    if strange:
        parser.error(f"--modes: unknown mode {strange[0]!r}; the modes are: model, current, identified")
    unknown = [name for names in effects for name in names if name not in CATALOGUE]
    if unknown:
        parser.error(f"--effects: unknown effect {unknown[0]!r}; the effects are: none, {', '.join(CATALOGUE)}")
    if args.laps < 1:
        parser.error(f"--laps: a path is run at least once, got {args.laps}")
    if args.laps > 1 and "own" in families:
        parser.error("--laps: the own family's paths are the repository's trajectories, run once; "
                     "give --families rigid,two_mass")
    mill = load_machine("demo_mill")
    plan = cases(2, args.seed) if args.fast else cases(args.cases, args.seed, effects)
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for family in families:
            for i, (names, seed) in enumerate(plan):
                for mode in modes:
                    if family == "own" and mode == "current":
                        continue  # the own family's traces log no current
                    case = run(family, mode, names, seed, mill, Path(folder), args.laps)
                    results.setdefault((family, mode), []).append(case)
                    named = ", ".join(e.label for e in case["named"]) or "nothing"
                    what = case["error"] or (f"named {named}; RMS {case['before'] or np.nan:.3f} -> {case['after'] or np.nan:.3f} µm "
                                             f"(noise {case['floor']:.3f})")  # a report's null (not finite) as nan
                    print(f"[{family}/{mode} {i + 1}/{len(plan)}] {'ok ' if case['right'] else 'BAD'} {case['path']:<20} "
                          f"hidden {' + '.join(t['name'] + '.' + t['axis'] for t in case['truths']) or 'none'}; "
                          f"{what}; effect {case['signal']:.3f} µm RMS; {case['seconds']:.1f} s for {case['duration']:.1f} s of trace",
                          file=sys.stderr, flush=True)
    columns = list(results)
    head = [f"{f}/{m}" for f, m in columns]
    width = 34
    print(f"{'':<{width}}" + "".join(f"{h:>24}" for h in head))
    lines = {key: summary(results[key]) for key in columns}
    for row in next(iter(lines.values())):
        print(f"{row:<{width}}" + "".join(f"{lines[key][row]:>24}" for key in columns))
    print("\nper effect: named right / cases (hidden effects all among those named) median parameter error, 2σ covered / "
          "found")
    for names in dict.fromkeys(effects):
        row = []
        for key in columns:
            these = [c for c in results[key] if tuple(t["name"] for t in c["truths"]) == names]
            errors = [e for c in these for e in c["parameter_errors"]]
            fit = f" {np.median(errors):.2f} {sum(x for c in these for x in c['covered'])}/{len(errors)}" if errors else ""
            row.append(f"{sum(c['right'] for c in these)}/{len(these)} ({sum(c['found'] for c in these)}){fit}" if these else "-")
        print(f"{'+'.join(names) or 'none':<{width}}" + "".join(f"{r:>24}" for r in row))


if __name__ == "__main__":
    main()
