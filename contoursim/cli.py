"""Command line: ``contoursim demo | simulate | compare | volumetric | diagnose | sweep``.

Every job prints a summary table to stdout and writes plots and traces to
``--out`` (default ``./contoursim-out``) through :func:`contoursim.output.output_dir`:
a directory that holds files but was not made by contoursim is never written
into, and in its own directories contoursim replaces only the files it wrote,
so nothing a user keeps there is overwritten. The directory is made only
once the job's files are read and its runs succeeded.

The commands import the simulation modules (python-control, scipy, numba,
matplotlib) when they run, so that ``contoursim --help`` answers at once.
"""

import argparse
import gc
import math
import os
import shutil
import sys
import warnings
from contextlib import contextmanager, nullcontext
from dataclasses import replace
from pathlib import Path

from . import _validate
from .config import TomlFile, local_file
from .exceptions import ConfigError, ContoursimWarning, OutputError, UnstableLoopError
from .output import output_dir

DEMO_MACHINE = "demo_mill"
DEMO_STRATEGIES = ("feedforward", "ccc_arc", "feedforward+ccc_arc")  # the demo's compact comparison, on its free-form run
DEMO_RUNS = {"iso230_4_circle": ("iso230_4_circle_ccw.toml", "iso230_4_circle_cw.toml"), "butterfly": ("butterfly.toml",)}
TOP_BLOCKS = 5  # the G-code blocks simulate prints, worst first
FILE_HELP = ("job .toml, path .toml or G-code (.nc .ngc .gcode .tap .cnc .mpf .iso .eia): a file, or a name in the "
             "trajectories library")
_JOB_KEYS = ("machine", "path", "feed", "work_offset", "geometric_compensation", "effect", "ballbar", "strategy")
_DIRECTIONS = ("ccw", "cw")
#: Servo periods beyond which a run takes minutes: said on stderr before it starts (a slow feed, a long path).
_LONG_RUN = 5_000_000


_COLUMNS = {"tracking max": "tracking_max_um", "tracking RMS": "tracking_rms_um", "contour max": "contour_max_um",
            "contour RMS": "contour_rms_um", "volumetric max": "volumetric_max_um"}


def _table(rows):
    """The summary table [µm], one row per run."""
    lines = [f"{'run [µm]':<36}" + "".join(f"{label:>16}" for label in _COLUMNS)]
    lines.append("-" * len(lines[0]))
    for name, summary in rows:
        lines.append(f"{name:<36}" + "".join(f"{summary[key]:>16.2f}" for key in _COLUMNS.values()))
    return "\n".join(lines)


def _trajectory(model, path_file, job=None, direction=None):
    """The path file's reference at the model's servo period, and its G-code program (None for a TOML path).

    A job's ``[feed]`` overrides the file's key by key; `direction` ("ccw" or
    "cw") replaces the path file's, for a circle, ISO 230-4 circle or helix.
    The motion waits at the end of each rapid (G0) for
    :func:`~contoursim.simulation.default_settle` seconds, a controller's
    in-position check: a cut starts with the axes in position. A run of the
    motion and the settle after it (:func:`run_job` appends it) longer than
    :data:`_LONG_RUN` servo periods is said on stderr (:func:`_say_long_run`).
    A motion too long for the memory is refused naming the job's ``[feed]``
    when it lengthens the path file's own motion, else the path file.
    """
    from .feed import sample
    from .model import as_model
    from .pathfile import library_file, override_feed, read_path_file
    from .simulation import default_settle

    own = read = read_path_file(path_file, direction)
    file = library_file(path_file)
    if job is not None and "feed" in job.data:
        read = override_feed(read, job)
    machine = as_model(model).machine
    settle = default_settle(machine)  # the settle after the run, and after each rapid (an in-position check)

    def plan(settings):
        return settings.plan(read.path, max_feed=machine.max_feed, in_position=settle,
                             servo_period=machine.servo_period)

    try:
        profile = plan(read.feed)
        try:
            trajectory = sample(read.path, profile, machine.servo_period)
        except ValueError as exc:  # too long for the memory: the job's [feed] when it made the file's motion longer
            if read is not own and _lengthens(plan, own, profile):
                raise _job_feed_error(exc, job, path_file) from None
            raise
        _say_long_run(profile.duration, settle, machine)
        return trajectory, read.program
    except ConfigError:
        raise
    except ValueError as exc:  # a feed above the machine's max feed, a run too large for the memory: naming the file
        primitive = getattr(exc, "primitive", None)  # and a feed by its line: a program's block's, a [feed] table's
        feed_key = ("feed", "feed_mm_min") if primitive is not None else ()
        if feed_key and read is not own and "feed_mm_min" in job.data["feed"]:  # the job's feed
            raise job.error(str(exc), *feed_key) from None
        if read.program is None:  # a path file's
            raise TomlFile.read(file).error(str(exc), *feed_key) from None
        raise _against_machine(exc, file, read.program) from None


def _lengthens(plan, own, profile):
    """Whether the motion `profile`, of a job's ``[feed]``, lasts longer than `plan` makes that of the path file `own`
    as read (a :class:`~contoursim.pathfile.PathFile`) with its own feed: the job's is what runs where the file's
    cannot (a feed above the machine's max feed)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the corners of a motion that does not run: not said
        try:
            return plan(own.feed).duration < profile.duration
        except ValueError:  # the file's own feed cannot run: the job's is what does
            return True


def _job_feed_error(exc, job, path_file):
    """The refusal `exc` of a motion a job's ``[feed]`` table makes too long, at the line of its key (of the table,
    for several keys)."""
    feed = job.data["feed"]
    given = ", ".join(f"{key} = {value:g}" for key, value in feed.items())
    return job.error(f"[feed] {given}, overriding {Path(path_file).name}'s: {exc}", "feed",
                     *(feed if len(feed) == 1 else ()))


def _say_long_run(motion, settle, machine):
    """Say on stderr a run of more than :data:`_LONG_RUN` servo periods: a motion of `motion` s and the settle of
    `settle` s after it, whose share is said when it is what makes the run long (its slowest position loop's 5/kp)."""
    from ._memory import RUN_BYTES_PER_SAMPLE

    dt = machine.servo_period
    periods = (motion + settle) / dt
    if periods <= _LONG_RUN:
        return
    held = ""
    if motion / dt <= _LONG_RUN or settle > motion:
        axis = machine.slowest_axis
        held = (f", of which {settle:.6g} s the settle after the path, 5/kp of axis {axis} "
                f"(kp_per_s = {machine.axes[axis].kp:.6g})")
    _stderr_line(f"contoursim: the run lasts {motion + settle:.6g} s{held}: {periods:.3g} servo periods of {dt:.6g} s "
                 f"to simulate, about {RUN_BYTES_PER_SAMPLE * periods / 1e9:.2g} GB of memory: this takes minutes")


def _against_machine(exc, path_file, program, job=None):
    """The error `exc` of a path against the machine (more coordinates than its axes, beyond their travel or max feed)
    naming the path's file, and a G-code `program`'s block where it does; a `job`'s work_offset line instead when it
    places the axis beyond its travel."""
    offset = job.data.get("work_offset", {}) if job is not None else {}
    key = next((key for key in offset if key.rpartition("_")[0] == getattr(exc, "axis", None)), None)
    if key is not None:
        return job.error(f"work_offset.{key} = {offset[key]:g}: {exc}", "work_offset", key)
    primitive = getattr(exc, "primitive", None)
    return ConfigError(str(exc), str(path_file), None if primitive is None or program is None else
                       int(program.lines[primitive]))


def _feed_override(job, path_file):
    """The line saying that a job's feed overrides a G-code program's F words; None where it does not apply."""
    from .gcode import SUFFIXES
    from .pathfile import library_file

    if (job is None or "feed_mm_min" not in job.data.get("feed", {})
            or library_file(path_file).suffix.lower() not in SUFFIXES):
        return None
    return (f"feed: {job.data['feed']['feed_mm_min']:g} mm/min from {Path(job.source).name}'s [feed], overriding the "
            "program's F words on every cutting block (G1/G2/G3); the rapids (G0) keep the rapid feed.")


def _check_memory(samples, dt, path_file, runs, advice):
    """Refuse `runs` runs of `samples` samples each (a path file's, settling included) that would not fit in memory."""
    from ._memory import check

    check(samples, f"{Path(path_file).name} runs for {samples * dt:.6g} s: at dt = {dt:.6g} s", advice, runs=runs)


def run_job(model, path_file, job=None, strategies=(), label=None, direction=None, runs=1):
    """Simulate `model` (a Model, or a Machine without effects) on a path file.

    A job file's ``[feed]`` table, when given, overrides the path file's key
    by key; `direction` ("ccw" or "cw") replaces the path file's. `runs` is
    the number of such runs the command will hold at once: refused before
    this one starts when they would not fit in the memory available.

    Returns
    -------
    tuple
        ``(name, path_file, result, program)``: the run's name (file stem or
        `label`), the path file, the :class:`~contoursim.simulation.SimResult`
        and the G-code :class:`~contoursim.gcode.Program` (None for a TOML path).
    """
    from .model import as_model
    from .simulation import default_settle, simulate

    trajectory, program = _trajectory(model, path_file, job, direction)
    # held here as simulate would hold it, so that the reference before holding is freed before the run
    trajectory = trajectory.held(default_settle(as_model(model).machine))
    if runs > 1:  # one run is checked when the reference is sampled
        _check_memory(len(trajectory), trajectory.dt, path_file, runs, "run fewer runs (no geometric compensation, "
                      "one direction, no nominal run) or a shorter path")
    name = label or Path(path_file).stem
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContoursimWarning)
        try:
            result = simulate(model, trajectory, strategies, settle=0.0)  # held already
        except UnstableLoopError:  # the machine with its effects, not the path
            raise
        except ValueError as exc:  # the path against the machine (its axes, their travel)
            raise _against_machine(exc, path_file, program, job) from None
    for warning in caught:  # say which run
        warnings.warn(f"{name}: {warning.message}", warning.category, stacklevel=2)
    return name, path_file, result, program


def _write(out, groups, every, nominal=None):
    """Write each run's trace CSV (every `every`-th sample), its blocks CSV (G-code) and the plots of each group.

    Parameters
    ----------
    groups : dict of str -> list of tuple
        Runs (from :func:`run_job`) that share plots, shown side by side, by the group's file stem.
    nominal : dict of str -> SimResult, optional
        The nominal run of each circular test, by run name: a difference-from-nominal polar plot too.

    Returns
    -------
    tuple
        The output folder, the table rows and, per G-code run, its
        :class:`~contoursim.gcode.BlockErrors` (written as ``NAME_blocks.csv``).
    """
    from .gcode import block_errors
    from .plotting import figure_files, save_figures
    from .traces import check_every

    for runs in groups.values():  # a trace every N leaves none of is refused before the folder is made
        for _, _, result, _ in runs:
            check_every(every, len(result.trajectory), result.machine.servo_period)
    out = output_dir(out)
    for name, runs in groups.items():  # every name refused before any file is written
        for run, _, result, program in runs:
            out.file(f"{run}.csv")
            if program is not None:
                out.file(f"{run}_blocks.csv")
        for figure in figure_files({run: result for run, _, result, _ in runs}, name, nominal):
            out.file(figure)
    blocks = {}
    for name, runs in groups.items():
        for run, path_file, result, program in runs:
            with out.write(f"{run}.csv") as stream:
                result.save_csv(stream, metadata={"path": Path(path_file).name}, every=every)
            if program is not None:
                blocks[run] = block_errors(program, result)
                with out.write(f"{run}_blocks.csv") as stream:
                    blocks[run].save_csv(stream)
        save_figures({run: result for run, _, result, _ in runs}, out, name, nominal)
    return out, [(run, result.summary()) for runs in groups.values() for run, _, result, _ in runs], blocks


def demo(args):
    """The README's main job: ISO 230-4 circles (CCW and CW, plotted together) and a free-form path on the demo machine."""
    from .comparison import Comparison
    from .compensation import strategies_named
    from .machine import load_machine, preset_file
    from .output import refused_early
    from .pathfile import library_file
    from .simulation import simulate

    refused_early(args.out, [f"{Path(f).stem}.csv" for files in DEMO_RUNS.values() for f in files])  # before the runs
    machine = load_machine(preset_file(DEMO_MACHINE, here=False))
    groups = {name: [run_job(machine, library_file(f)) for f in files] for name, files in DEMO_RUNS.items()}
    (_, free_form, plain, _), = groups["butterfly"]
    compared = {"none": plain}
    compared.update((name, simulate(machine, plain.trajectory, strategies_named(name), settle=0.0))
                    for name in DEMO_STRATEGIES)  # on the same reference, already held at its end
    out, rows, _ = _write(args.out, groups, args.every)
    print(f"contoursim demo — machine: {machine.name}, servo period {1e3 * machine.servo_period:g} ms")
    print("Tracking error is the lag behind the interpolator (≈ v/Kp); contour error is the distance to the path.")
    print("Both over the test proper: the full test circle of the ISO 230-4 runs (the CSV's measuring = 1 rows).")
    print(_table(rows))
    print(f"\nCompensation strategies on {Path(free_form).stem} (all of them, with plots: contoursim compare {Path(free_form).stem}):")
    print(Comparison(compared).table())
    print(f"\nplots and traces written to {out}/")


def _job(args, extra_keys=()):
    """Model, path file, job file (or None) and geometric switch of ``simulate FILE``.

    FILE is a job file (a TOML with ``machine`` and ``path`` keys, both naming
    presets/library entries or files relative to the job, and optionally a
    ``[feed]`` table, ``work_offset``, ``geometric_compensation``,
    ``[[effect]]`` tables, added to the machine file's, and for ``simulate`` a
    ``[ballbar]`` table, see :func:`_ballbar`) or a bare path file, run
    on ``--machine`` (default: the demo machine). A job file names its
    machine, so ``--machine`` with a job file is an error. `extra_keys`: the
    further top-level keys a file built on a job file has (a sweep spec's).
    """
    from .machine import preset_file, read_work_offset
    from .model import load_model, with_file_effects
    from .pathfile import NAME_SUFFIXES, library_file

    file = Path(args.file)
    if file.suffix == ".toml" and file.exists():
        job = TomlFile.read(file)
        if job.kind() == "job":
            spec = next((key for key in ("sweep", "vary") if key in job.data and key not in extra_keys), None)
            if spec is not None:  # said so, not an unknown key 'strategies' (did you mean 'strategy'?)
                raise job.error("this is a sweep spec ([sweep] and [[vary]] tables): run it with contoursim sweep", spec)
            if "machine" not in job.data:
                job.table(allowed=_JOB_KEYS + tuple(extra_keys))  # a misspelt machine key said as such
                raise job.error('a job file names its machine: add machine = "<preset name or machine file>" '
                                '(e.g. "demo_mill"), or give a path file')
            data = job.table(allowed=_JOB_KEYS + tuple(extra_keys), required=("machine", "path"),
                             text=dict.fromkeys(("machine", "path"), "a name or a file name"))
            if args.machine is not None:
                raise job.error(f"--machine {args.machine} is not used with a job file, which names its machine "
                                f"({data['machine']!r}); drop one of them", "machine")
            if "ballbar" in data and args.command != "simulate":
                raise job.error(f"[ballbar] is for contoursim simulate; {args.command} runs the path as the file gives it",
                                "ballbar")
            geometric = data.get("geometric_compensation", False)
            if not isinstance(geometric, bool):
                raise job.error(f"geometric_compensation must be true or false, got {geometric!r}", "geometric_compensation")
            def named(key, find, shipped, suffixes):
                near = local_file(data[key], file.parent, suffixes)  # beside the job, else a preset's or entry's name
                if near is not None and near.is_dir():  # '', '.', a folder beside the job: said where the job names it
                    raise job.error(f"{key} = {data[key]!r} names the folder {near}, not a {key} file", key)
                if near is not None and os.path.samefile(near, file):  # pocket.toml with path = "pocket"
                    raise job.error(f"{key} = {data[key]!r} names this job file itself: a job named as a {key} it "
                                    f"runs hides that {key}; rename the job file (e.g. {file.stem}_job.toml)", key)
                try:  # never a file of the current folder: the job would run differently from elsewhere
                    return find(shipped(data[key], here=False) if near is None else near)
                except ConfigError as exc:
                    if exc.source is None:  # a name that is no file and no preset: said where the job names it
                        raise job.error(f"{exc} (a job's files are looked for beside it, in "
                                        f"{file.parent.resolve()})", key) from None
                    raise

            model = named("machine", load_model, preset_file, (".toml",))
            machine = model.machine
            if "work_offset" in data:
                machine = replace(machine, work_offset={**machine.work_offset, **read_work_offset(job, machine.chain)})
            model = with_file_effects(replace(model, machine=machine), job)
            if geometric and machine.chain is None:  # simulate's, compare's and a sweep's, said where the job asks
                raise job.error(_no_chain(machine), "geometric_compensation")
            return model, named("path", lambda near: near, library_file, NAME_SUFFIXES), job, geometric
    return load_model(args.machine or preset_file(DEMO_MACHINE, here=False)), library_file(args.file), None, False


def _no_chain(machine):
    """Why geometric compensation cannot run on `machine`, which has no geometric model."""
    return f"{machine.name} has no geometric model ([[body]] tables) to compensate with"


def _ballbar(job):
    """The ``[ballbar]`` table of a job file: ``(directions, subtract_nominal)``, or None without one.

    ``directions`` (default ``["ccw", "cw"]``) runs the path file's circle in
    each sense, the runs overlaid in one polar plot; ``subtract_nominal =
    true`` adds a difference-from-nominal polar plot: each run minus the same
    run of the machine without any ``[[effect]]`` (the machine file's and the
    job's), which takes the servo's own signature out and leaves the effects'.
    """
    if job is None or "ballbar" not in job.data:
        return None
    spec = job.table("ballbar", allowed=("directions", "subtract_nominal"))
    directions = spec.get("directions", list(_DIRECTIONS))
    if (not isinstance(directions, list) or not directions or any(d not in _DIRECTIONS for d in directions)
            or len(set(directions)) != len(directions)):
        raise job.error(f'directions must be a list of "ccw" and "cw", each at most once, got {directions!r}',
                        "ballbar", "directions")
    subtract = spec.get("subtract_nominal", False)
    if not isinstance(subtract, bool):
        raise job.error(f"subtract_nominal must be true or false, got {subtract!r}", "ballbar", "subtract_nominal")
    return tuple(directions), subtract


def simulate_command(args):
    """``contoursim simulate FILE``: see :func:`_job`. Nothing is written unless every run succeeds."""
    import re

    from .gcode import DIALECT
    from .geocomp import GeometricCompensation
    from .model import Model
    from .output import refused_early
    from .pathfile import load_path_file

    model, path_file, job, geometric = _job(args)
    machine = model.machine
    if job is not None and "strategy" in job.data:
        raise job.error("[[strategy]] tables set the strategies of contoursim compare; simulate runs none", "strategy")
    if args.geometric_compensation and machine.chain is None:
        raise ConfigError(f"--geometric-compensation: {_no_chain(machine)}")
    ballbar = _ballbar(job)
    if ballbar is not None and load_path_file(path_file)[0].test_circle() is None:
        raise job.error(f"[ballbar] needs a circular test: {Path(path_file).name} has no test circle (use a path of "
                        'type = "iso230_4_circle")', "ballbar")
    stem = Path(path_file).stem if ballbar is None else re.sub(r"_c?cw$", "", Path(path_file).stem)
    directions, subtract = ballbar or ((None,), False)
    variants = [("", [])] + ([("_geometric_comp", [GeometricCompensation(machine.chain)])]
                             if geometric or args.geometric_compensation else [])
    names = {(direction, suffix): (stem if direction is None else f"{stem}_{direction}") + suffix
             for direction in directions for suffix, _ in variants}
    refused_early(args.out, [f"{name}.csv" for name in names.values()])  # a file for --out: not after the runs
    total = len(directions) * len(variants) * (2 if subtract else 1)  # the runs held at once
    runs, nominal = [], {}
    for direction in directions:
        for suffix, strategies in variants:
            name = names[direction, suffix]
            runs.append(run_job(model, path_file, job, strategies, label=name, direction=direction,
                                runs=1 if runs else total))  # fmt: skip
            if subtract:  # the same run on the machine without effects
                nominal[name] = run_job(Model(machine), path_file, job, strategies, direction=direction)[2]
    out, rows, blocks = _write(args.out, {stem: runs}, args.every, nominal or None)
    effects = "; ".join(f"{e.label} ({_set_values(e)})" for e in model.effects) or "none"
    print(f"contoursim simulate — machine: {machine.name}, path: {Path(path_file).name}, effects: {effects}")
    if blocks:
        print(f"G-code: {DIALECT}.")
        if _feed_override(job, path_file):
            print(_feed_override(job, path_file))
        print("Errors over the cutting moves (G1/G2/G3: the CSV's measuring = 1 rows); the rapids (G0, rapid = 1) "
              "are not scored.")
    print(_table(rows))
    for run, errors in blocks.items():
        print(f"\n{run}: the worst cutting blocks, max over each [µm] ({min(TOP_BLOCKS, (~errors.rapid).sum())} of "
              f"{(~errors.rapid).sum()}; every block in {run}_blocks.csv)")
        print(errors.table(TOP_BLOCKS))
    if ballbar is not None:
        _print_ballbar(runs, nominal)
    print(f"\nplots and traces written to {out}/")


def _print_ballbar(runs, nominal):
    """Circularity of each run of a ballbar job [µm], and of its difference from the nominal run."""
    from .plotting import circular_deviation, deviation_from_nominal

    print()
    for run, _, result, _ in runs:
        test = circular_deviation(result)
        line = f"{run} ({test['direction']}): circularity {test['circularity']:.2f} µm, mean deviation " \
               f"{test['deviation'].mean():.2f} µm"
        if run in nominal:
            line += f"; minus the nominal run: range {deviation_from_nominal(result, nominal[run])['circularity']:.2f} µm"
        print(line)


def _set_values(effect):
    """``name = value`` of an effect's size and of every parameter or option not at its default."""
    kind = effect.kind
    values = [f"{p.name} = {p.value:g}" for i, (p, default) in enumerate(zip(effect.parameters, kind.parameters))
              if i == 0 or p.value != default.value]  # fmt: skip
    values += [f"{key} = {value!r}" for key, value in effect.set_options().items()]
    return ", ".join(values)


def _strategy_settings(job, names):
    """A job file's ``[[strategy]]`` tables: strategy name -> keyword arguments (see ``STRATEGY_KEYS``).

    `names`: the strategies the command runs (comparison names, parts joined by '+'); a table of a strategy none
    of them has is refused by its line (its settings would be dropped without a word).
    """
    from .compensation import STRATEGY_KEYS, strategy_setting

    raw = job.data.get("strategy", [])
    if not isinstance(raw, list) or not all(isinstance(item, dict) for item in raw):
        raise job.error("strategy must be an array of tables ([[strategy]])", "strategy")
    settings = {}
    for i, item in enumerate(raw):
        name = item.get("name")
        if name not in STRATEGY_KEYS:
            raise job.error(f"[[strategy]] needs name = one of {', '.join(map(repr, STRATEGY_KEYS))}, got {name!r}",
                            "strategy", i, *(("name",) if "name" in item else ()))
        if name in settings:
            raise job.error(f"strategy {name!r} has a [[strategy]] table already: one per strategy",
                            "strategy", i, "name")
        if name not in {part for text in names for part in text.split("+")}:
            raise job.error(f"[[strategy]] {name}: no strategy run here has it (strategies {','.join(names)}): run it, "
                            "or drop the table", "strategy", i, "name")
        job.table("strategy", i, allowed=("name", *STRATEGY_KEYS[name]))
        settings[name] = {}
        for key, value in item.items():
            if key != "name":
                try:
                    settings[name][key] = strategy_setting(name, key, value)
                except ValueError as exc:
                    raise job.error(f"[[strategy]] {name}: {exc}", "strategy", i, key) from None
    return settings


def _set_option(settings, text):
    """``--set NAME.KEY=VALUE`` into `settings` (strategy name -> keyword arguments), as a ``[[strategy]]`` key; NAME."""
    from .compensation import strategy_setting

    where, equals, value = text.partition("=")
    name, dot, key = where.strip().partition(".")
    if not equals or not dot:
        raise ValueError(f"--set {text}: write STRATEGY.KEY=VALUE, e.g. ccc_arc.kp_per_s=120")
    try:
        number = int(value) if value.strip().lstrip("+-").isdigit() else float(value)
        if math.isinf(float(number)) and "inf" not in value.lower():
            raise OverflowError(value)
    except OverflowError:  # 1e400, or a whole number beyond a float's range
        raise ValueError(f"--set {where}={_validate.shown(value.strip())}: too large a number, beyond "
                         f"±{_validate.FLOAT_MAX:.4g}") from None
    except ValueError:
        raise ValueError(f"--set {where}={_validate.shown(value.strip())}: {_validate.shown(repr(value.strip()))} "
                         "is not a number") from None
    try:
        settings.setdefault(name, {})[key.strip()] = strategy_setting(name, key.strip(), number)
    except ValueError as exc:
        raise ValueError(f"--set {text}: {exc}") from None
    return name


def compare_command(args):
    """``contoursim compare FILE [--strategies a,b] [--set S.K=V] [--tune] [--json R.json]``: strategies side by side.

    FILE as for ``simulate``; a job's ``geometric_compensation = true`` adds the strategy ``geometric``
    unless one of the strategies composes it already.
    """
    from .comparison import JSON_FORM, compare
    from .compensation import STRATEGY_NAMES
    from .output import atomic_write, refused_early, report_file
    from .plotting import comparison_files, save_comparison_figures
    from .simulation import default_settle

    model, path_file, job, geometric = _job(args)
    names = STRATEGY_NAMES if args.strategies is None else args.strategies
    if geometric and not any("geometric" in name.split("+") for name in names):  # the job's second run, as simulate's
        names = [*names, "geometric"]
    settings = {} if job is None else _strategy_settings(job, names)
    parts = {part for name in names for part in name.split("+")}
    given = {}  # each --set's STRATEGY.KEY: one given twice would drop the first without a word
    for text in args.set or ():
        where = "".join(text.partition("=")[0].split())
        if where in given:
            raise ValueError(f"--set {where} is given twice ({given[where]}, {text}): give it once")
        given[where] = text
        if _set_option(settings, text) not in parts:  # a setting of a strategy that does not run: dropped otherwise
            raise ValueError(f"--set {text}: no strategy run here has {text.partition('.')[0].strip()!r} "
                             f"(--strategies {','.join(names)}): run it, or drop the setting")
    if args.tune and not any(part.startswith("ccc_") for part in parts):
        raise ValueError(f"--tune tunes a cross-coupled strategy's gains; none runs here (--strategies {','.join(names)})")
    names, left_out = (names, None) if args.tune else _designable(model, names, settings, args.strategies is None)
    plots = comparison_files(Path(path_file).stem)
    report = report_file(args.json, JSON_FORM, "comparison JSON", args.out, written=plots)  # no user's file, no plot
    refused_early(args.out, plots)  # a user's file of a plot's name: not after the comparison
    (trajectory, program), dt = _trajectory(model, path_file, job), model.machine.servo_period
    _check_memory(len(trajectory) + math.ceil(default_settle(model.machine) / dt), dt, path_file, len(names),
                  "compare fewer strategies (--strategies) or a shorter path")
    try:
        model.machine.axis_commands(trajectory)  # the path against the machine, as simulate's run_job says it
    except ValueError as exc:  # (more coordinates than its axes, beyond their travel)
        raise _against_machine(exc, path_file, program, job) from None
    comparison = compare(model, trajectory, names, settings=settings, tuned=args.tune)
    out = output_dir(args.out)
    save_comparison_figures(comparison, out, Path(path_file).stem)
    if report is not None:  # the files before the table: a reader gone half-way (| head) costs none of them
        with atomic_write(report) as stream:
            stream.write(comparison.to_json() + "\n")
    machine = comparison.runs[names[0]].machine
    print(f"contoursim compare — machine: {machine.name}, path: {Path(path_file).name}; errors over the test proper")
    if _feed_override(job, path_file):
        print(_feed_override(job, path_file))
    if left_out:
        print(left_out)
    print(comparison.table())
    if report is not None:
        print(f"\ncomparison written to {report}")
    print(f"plots written to {out}/")


def _designable(model, names, settings, drop):
    """`names` without the strategies whose coupling gains are to be designed on loops too little damped for it, and
    the line that says so (`drop`: the default set); else such a strategy is refused, saying how to give its gains."""
    from .compensation import strategies_named

    servos, dt = model.machine.axes, model.machine.servo_period
    kept, why = [], None
    for name in names:
        strategies = strategies_named(name, chain=model.machine.chain, settings=settings)  # a composition's own errors
        try:
            for strategy in strategies:
                strategy.settings(servos, dt)
        except ValueError as exc:
            coupled = next((part for part in name.split("+") if part.startswith("ccc_")), None)
            if coupled is None:  # not a coupling's design: the comparison says it as it would
                raise
            # gains given or tuned run where the design found the loops too little damped; on one axis nothing does
            said = str(exc) + (f" (--set {coupled}.kp_per_s=... --set {coupled}.ki_per_s2=..., or a [[strategy]] "
                               "table), or tune them (--tune)" if len(servos) > 1 else "")
            if not drop:
                raise ValueError(f"--strategies {name}: {said}") from None
            why = why or said
            continue
        kept.append(name)
    if not kept:
        raise ValueError(f"no strategy runs: {why}")
    left = [name for name in names if name not in kept]
    return kept, (f"left out: {', '.join(left)} — {why}" if left else None)


def volumetric(args):
    """``contoursim volumetric MACHINE``: worst volumetric errors and error-field plots."""
    from .machine import preset_file
    from .volumetric import volumetric_report

    print(volumetric_report(preset_file(args.machine), args.out))


def diagnose_command(args):
    """``contoursim diagnose MEASURED.csv [--model M.toml] [--report R.json]``: name what the nominal model lacks.

    Several traces, or a folder of them: :func:`fleet_command`.
    """
    from ._memory import check_diagnosis
    from .diagnosis import FIGURE_FILES, REPORT_FORM, REPORT_OPTIONAL, diagnose, save_figures
    from .machine import _file_names
    from .model import load_model
    from .output import refused_early, report_file, writing
    from .traces import read_trace

    if len(args.file) > 1 or Path(args.file[0]).is_dir():
        return fleet_command(args)
    if args.summary or args.scheduler:
        raise ValueError("--summary and --scheduler are for several traces (or a folder of them); one trace runs here")
    args.file = args.file[0]
    trace = read_trace(args.file)
    model = load_model(args.model, check=False) if args.model else None  # the trace judges its loops' stability
    check_diagnosis(trace, model, args.file)
    report = report_file(args.report, REPORT_FORM, "diagnosis report", args.out,  # never a user's file,
                         written=(*FIGURE_FILES, "corrected_model.toml"), also=REPORT_OPTIONAL)  # nor one the run writes
    corrected = Path(args.out) / "corrected_model.toml"
    if args.model and corrected.is_file() and Path(args.model).is_file() and os.path.samefile(corrected, args.model):
        raise ConfigError(f"--out {args.out} would replace {args.model}, the model this run reads, with this trace's "
                          "corrected model: give another --out")
    refused_early(args.out, (*FIGURE_FILES, "corrected_model.toml"))  # not after the diagnosis
    print(f"contoursim diagnose — {Path(args.file).name}: axes {', '.join(trace.axes)}, {trace.t.size} samples every "
          f"{1e3 * trace.dt:.4g} ms; nominal model: {args.model or 'identified from the trace'}", flush=True)
    try:
        result = diagnose(trace, model, progress=_progress_line(sys.stderr))
    except ConfigError:  # naming its own file (the model's)
        raise
    except UnstableLoopError as exc:  # a loop of the model no plant within its prior makes stable
        raise UnstableLoopError(f"{args.model}: {_file_names(exc)}", exc.margins) from None  # its keys, as simulate's
    except ValueError as exc:  # what the trace cannot give: naming it
        raise ConfigError(str(exc), args.file) from None
    finally:
        if sys.stderr.isatty():
            sys.stderr.write("\n")
    out = output_dir(args.out)  # before the report: a refused folder leaves no report of a run that ended in an error
    out.file("corrected_model.toml")  # a file of the user's there: refused before anything is written
    save_figures(result, out)  # its figures refused before it writes any
    with out.write("corrected_model.toml") as stream:
        stream.write(result.corrected_model(args.model))
    if report is not None:  # the files before the story: a reader gone half-way (| head) costs none of them
        with writing(report, overwrite=True) as stream:
            stream.write(result.to_json() + "\n")
    print(result.report())
    if report is not None:
        print(f"report written to {report}")
    print(f"plots and the corrected model (corrected_model.toml, for diagnose --model on another experiment) "
          f"written to {args.out}/")


def _progress_line(stream):
    """A progress callback writing to `stream`: on a terminal each line replaces the last (one line), else one per line."""
    if not stream.isatty():
        return lambda line: print(line, file=stream, flush=True)

    def say(line):
        stream.write("\r" + line[: shutil.get_terminal_size().columns - 1] + "\x1b[K")
        stream.flush()
    return say


def sweep_command(args):
    """``contoursim sweep SPEC.toml [--scheduler ADDRESS|local:N]``: every variant of a spec, one table row each."""
    from .output import refused_early
    from .sweep import FIGURES, Progress, diverged_why, read_sweep, run_sweep, table_files, write_results

    sweep = read_sweep(args.spec)
    # a user's file of the table's or a plot's name: not after the sweep; those of the best and worst runs depend on
    # its results (whether any variant ran, whether their path is a circular test): write_results refuses them
    refused_early(args.out, table_files(sweep))
    where = "this process" if args.scheduler is None else f"dask scheduler {args.scheduler}"
    print(f"contoursim sweep — {Path(args.spec).name}: {len(sweep.values)} variants of {', '.join(sweep.names)}; "
          f"strategies {sweep.strategies}; on {where}", flush=True)
    with Progress() as progress:
        table = run_sweep(sweep, args.scheduler, progress=progress)
    out, chosen = write_results(sweep, table, args.out)
    diverged = int(table[:, FIGURES.index("diverged")].sum())
    print(f"{diverged} of {len(table)} variants diverged or were refused by a loop check (the axes' or the coupled loop's)")

    def values(i):
        return ", ".join(f"{n} = {v:.6g}" for n, v in zip(sweep.names, sweep.values[i]))

    if diverged:  # the first one's reason: the margins that say how far it is
        first = next(i for i, row in enumerate(table) if row[FIGURES.index("diverged")])
        print(f"the first, variant {first} ({values(first)}): {diverged_why(sweep, first)}")
    if chosen is not None:
        for label, i in zip(("best", "worst"), chosen):
            figures = dict(zip(FIGURES, table[i]))
            print(f"{label:<6} variant {i}: {values(i)}: contour max {figures['contour_max_um']:.4g} µm, "
                  f"RMS {figures['contour_rms_um']:.4g} µm, peak current {figures['peak_current_A']:.4g} A")
    print(f"table, plots{' and the best and worst runs' if chosen is not None else ''} written to {out}/")


def fleet_command(args):
    """``contoursim diagnose A.csv B.csv … | DIR [--summary FLEET.json] [--scheduler …]``: a report per trace, a fleet summary.

    A trace that fails is listed with why; when every trace fails, the summary is written and the command ends in
    an error (exit status 2).
    """
    import json

    import matplotlib.pyplot as plt

    from .fleet import SUMMARY_FORM, SUMMARY_OPTIONAL, diagnose_fleet, fleet_summary, plot_fleet, trace_files
    from .output import refused_early, report_file, writing
    from .sweep import Progress

    if args.report:
        raise ValueError("--report names one trace's report: with several traces each report goes to --out, "
                         "and --summary FLEET.json gets the fleet's")
    files = trace_files(args.file)
    stems = [f.stem for f in files]
    twice = sorted({stem for stem in stems if stems.count(stem) > 1})
    if twice:  # each trace's report is <stem>.json beside fleet.json
        raise ValueError(f"two traces named {twice[0]}.csv: their reports would share a file name; rename one")
    if "fleet" in stems:
        raise ValueError(f"the trace {files[stems.index('fleet')]}'s report would be fleet.json, the fleet summary's "
                         "file; rename the trace")
    summary_file = report_file(args.summary, SUMMARY_FORM, "fleet summary", args.out,  # never a file the user keeps
                               written=[f"{stem}.json" for stem in stems] + ["fleet.png"],  # nor a trace's report
                               also=SUMMARY_OPTIONAL)
    refused_early(args.out, [f"{stem}.json" for stem in stems] + ["fleet.json", "fleet.png"])  # not after the fleet
    where = "this process" if args.scheduler is None else f"dask scheduler {args.scheduler}"
    print(f"contoursim diagnose — {len(files)} traces; nominal model: {args.model or 'identified from each trace'}; "
          f"on {where}", flush=True)
    with Progress("diagnose", "traces") as progress:
        outcomes = diagnose_fleet(files, args.model, args.scheduler, progress=progress)
    summary = fleet_summary(outcomes)
    out = replace(output_dir(args.out), by="fleet")  # each file recorded as a fleet's
    written = [f"{Path(o['trace']).stem}.json" for o in outcomes if "report" in o] + ["fleet.json", "fleet.png"]
    for name in written:
        out.file(name)  # every name refused before any file is written
    for outcome in outcomes:
        if "report" in outcome:
            with out.write(f"{Path(outcome['trace']).stem}.json") as stream:
                stream.write(json.dumps(outcome["report"], indent=2, ensure_ascii=False) + "\n")
    # an earlier fleet's reports of traces this one did not diagnose (failed now, or not in it) would stand beside it
    for name in out.written_by("fleet") - set(written):
        out.remove(name)
    text = json.dumps(summary, indent=2, ensure_ascii=False) + "\n"
    with out.write("fleet.json") as stream:
        stream.write(text)
    if summary_file is not None:
        with writing(summary_file, overwrite=True) as stream:
            stream.write(text)
    fig = plot_fleet(summary)
    with out.write("fleet.png", binary=True) as stream:
        fig.savefig(stream, format="png", dpi=100)
    plt.close(fig)
    print(f"{summary['diagnosed']} of {summary['traces']} traces diagnosed; explained by the nominal model: "
          f"{len(summary['nominal'])}; no effect named, more than noise left: {len(summary['unexplained'])}")
    for label, e in summary["effects"].items():
        spread = "; ".join(f"{key} {d['min']:.4g} … {d['max']:.4g} (median {d['median']:.4g})"
                           for key, d in e["parameters"].items())
        print(f"  {label:<24} on {e['count']:>3} of {summary['traces']} traces: {spread}")
    for failed in summary["failed"]:
        print(f"  failed: {failed['trace']}: {failed['error']}")
    also = f"; summary to {summary_file}" if summary_file else ""
    if not summary["diagnosed"]:  # a fleet of failures is an error (exit 2), its summary written to say why
        print(f"no report; fleet.json and fleet.png (the failures) written to {out}/{also}")
        raise ValueError(f"none of the {summary['traces']} traces could be diagnosed: why, above and in "
                         f"{out.path / 'fleet.json'}")
    reports = f"{summary['diagnosed']} report{'s' if summary['diagnosed'] > 1 else ''}"
    print(f"{reports} (one per trace diagnosed), fleet.json and fleet.png written to {out}/{also}")


def _names(text):
    """``--strategies A,B``: the comma-separated names, at least one."""
    names = ["+".join(part.strip() for part in n.split("+")) for n in text.split(",") if n.strip()]  # "a + b": a+b
    if not names:
        raise argparse.ArgumentTypeError(f"names no strategy; got {text!r} (e.g. none,ccc_arc)")
    return names


def _written(what, example):
    """The type of an option naming where contoursim writes `what` (into a folder, to a file): any name but ``-``,
    which a command-line user means as standard output, where contoursim prints its table (`example`: a name)."""

    def name(text):
        if not text.strip():
            raise argparse.ArgumentTypeError(f"names nothing; contoursim writes {what}: name one, e.g. {example}")
        if text.strip() == "-":
            raise argparse.ArgumentTypeError(f"contoursim writes {what}, not to standard output ('-'): name one, "
                                             f"e.g. {example}")
        return text

    return name


def _every(text):
    """``--every N``: a whole number >= 1."""
    try:
        return _validate.positive_int("--every", int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of samples, at least 1; got {text!r}") from None


def main(argv=None, compile_notice=False):
    """Entry point of the ``contoursim`` command.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: the process's).
    compile_notice : bool
        Say on stderr when numba compiles contoursim's functions, and how
        long that took (:func:`_compile_notice`); the program does.

    Returns
    -------
    int
        The exit status: 0, 2 for an error of the user's, 130 when interrupted.
    """
    parser = argparse.ArgumentParser(prog="contoursim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="ISO 230-4 circle tests and a free-form path on the demo machine")
    p.set_defaults(run=demo)
    p = sub.add_parser("simulate", help="simulate a job file (machine + path) or a path file")
    p.add_argument("file", help=FILE_HELP)
    p.add_argument("--machine", help="machine preset or file for a bare path file (default: demo_mill)")
    p.add_argument("--geometric-compensation", action="store_true", help="also run with geometric compensation")
    p.set_defaults(run=simulate_command)
    p = sub.add_parser("compare", help="compensation strategies side by side on a job file or a path file")
    p.add_argument("file", help=FILE_HELP)
    p.add_argument("--machine", help="machine preset or file for a bare path file (default: demo_mill)")
    p.add_argument("--strategies", metavar="A,B,...", type=_names,
                   help="strategies to run, comma-separated (default: none,feedforward,zpetc,ccc_linear,ccc_arc,"
                        "feedforward+ccc_arc); parts joined by '+' compose, 'geometric' too")
    p.add_argument("--set", action="append", metavar="S.KEY=VALUE",
                   help="a strategy's setting, as in a job file's [[strategy]] table (e.g. ccc_arc.kp_per_s=120); "
                        "repeat for more")
    p.add_argument("--tune", action="store_true",
                   help="tune each cross-coupled strategy's kp, ki on this path under the coupled-loop check")
    p.add_argument("--json", metavar="R.json", type=_written("the comparison JSON to a file", "--json r.json"),
                   help="write the comparison (JSON) to this file")
    p.set_defaults(run=compare_command)
    p = sub.add_parser("volumetric", help="volumetric error map of a machine preset or file")
    p.add_argument("machine", help="machine preset name or file")
    p.set_defaults(run=volumetric)
    p = sub.add_parser("diagnose", help="name the effects a nominal model lacks to explain a measured trace")
    p.add_argument("file", nargs="+",
                   help="measured trace CSV (t, x_ref, x[, y_ref, y[, z_ref, z]]); several, or a folder: a fleet")
    p.add_argument("--model", help="nominal machine file or preset (default: identified from the trace)")
    p.add_argument("--report", type=_written("the diagnosis report to a file", "--report report.json"),
                   help="write the diagnosis report (JSON) to this file")
    p.add_argument("--summary", metavar="FLEET.json", type=_written("the fleet summary to a file", "--summary fleet.json"),
                   help="several traces: write the fleet summary (JSON) to this file")
    p.add_argument("--scheduler", metavar="ADDRESS|local:N",
                   help='several traces: diagnose them on a dask cluster (needs pip install "contoursim[distributed]")')
    p.set_defaults(run=diagnose_command)
    p = sub.add_parser("sweep", help="many variants of a job (axis settings, effects, strategy gains): a table of figures")
    p.add_argument("spec", help="sweep spec .toml: a job file with [sweep] and [[vary]] tables")
    p.add_argument("--scheduler", metavar="ADDRESS|local:N",
                   help="run on a dask cluster: a scheduler address, or local:N worker processes on this machine "
                        '(needs pip install "contoursim[distributed]")')
    p.set_defaults(run=sweep_command)
    for p in sub.choices.values():
        p.add_argument("--out", default="contoursim-out", type=_written("its plots and files into a folder", "--out results"),
                       help="output directory (default: ./contoursim-out)")
    for command in ("demo", "simulate"):
        sub.choices[command].add_argument("--every", type=_every, default=1, metavar="N",
                                          help="write every Nth sample to the trace CSV (default: 1, all, exact to the nm)")
    args = parser.parse_args(argv)

    shown = set()  # each warning once: a file read for each of several runs warned once a run

    def show(message, category, filename, lineno, *details):
        if issubclass(category, ContoursimWarning):
            line = f"contoursim {args.command}: warning: {message}"
        else:  # a backstop: one line, saying where (the sources of such warnings are guarded)
            line = (f"contoursim {args.command}: warning: {category.__name__}: {message} "
                    f"({Path(filename).name}, line {lineno})")
        if line not in shown:
            shown.add(line)
            _stderr_line(line)

    try:
        with warnings.catch_warnings(), _compile_notice(args.command) if compile_notice else nullcontext():
            warnings.simplefilter("always", ContoursimWarning)
            warnings.showwarning = show
            args.run(args)
    except (ConfigError, UnstableLoopError, ValueError, TypeError, FileExistsError, OutputError) as exc:
        print(f"contoursim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of the output is gone: run() ends the program
        raise
    except OSError as exc:  # a backstop: a file the checks above did not name
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"contoursim {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except MemoryError:  # a backstop: the memory checks estimate, the system decides
        print(f"contoursim {args.command}: error: out of memory: the job needs more than this machine has free; "
              "files already complete are kept", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"contoursim {args.command}: interrupted; files already complete are kept, none is left half-written",
              file=sys.stderr)
        return 130
    return 0


@contextmanager
def _compile_notice(command):
    """Say on stderr when contoursim's numba functions compile (a first run: a cold cache), and then how long it took."""
    from numba.core.event import install_listener

    from ._numba import CompileClock

    clock = CompileClock(lambda: _stderr_line(f"contoursim {command}: compiling the numba functions of the simulation, "
                                              "once (later runs load them from the cache) ..."))
    try:
        with install_listener("numba:compile", clock):
            yield
    finally:
        if clock.seconds:
            _stderr_line(f"contoursim {command}: compiled in {clock.seconds:.1f} s")


def _stderr_line(text):
    """Print `text` as a line of its own on stderr: on a terminal, over the progress line showing there
    (:func:`_progress_line`), which the next progress line writes again below it."""
    print(("\r\x1b[K" if sys.stderr.isatty() else "") + text, file=sys.stderr, flush=True)


def run():
    """The ``contoursim`` program (and ``python -m contoursim``): :func:`main` tuned for a whole process.

    - A first run (a cold numba cache) says on stderr that it compiles,
      once, and how long that took (:func:`_compile_notice`).
    - Python's cycle collector looks at the young objects once 10,000 more
      have been made than freed, not 700: numba's compiler and matplotlib
      make many objects and few cycles, and in a first ``contoursim demo``
      the default ran it 1,166 times, 0.69 s of CPU (0.28 s at 10,000).
    - A hard exit: when a command returns, its files are closed and
      complete; a normal exit would still free the objects of numba,
      matplotlib and python-control one by one, 0.25 s of CPU after
      ``contoursim demo``. The program flushes its output and ends the
      process instead (as mypy does). When the reader of its output has
      gone (``contoursim demo | head``), it ends there with status 1
      and no traceback; the files completed by then are kept. When
      its output cannot be written (to a file on a full disk), it says
      so in a line and ends with status 2.
    - A terminal or pipe whose encoding cannot show a character the
      program prints (µ, —, ζ under ``PYTHONIOENCODING=ascii`` or a C
      locale without UTF-8 mode) shows its escape (``\\xb5``) instead
      of failing once the work is done.

    :func:`main` itself leaves the process as it is, for callers in Python.
    """
    gc.set_threshold(10_000, 10, 10)
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):  # a text stream of the process (None when closed; a caller's StringIO)
            stream.reconfigure(errors="backslashreplace")
    try:
        code = main(compile_notice=True)
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:  # None: started with the descriptor closed (contoursim demo >&-)
                stream.flush()
    except BrokenPipeError:  # the reader of the output is gone (contoursim demo | head): no traceback
        code = 1
    except OSError as exc:  # the table to a file on a full disk (contoursim demo > log.txt): said, not a traceback
        if code == 0:  # else the command has said its error (the same one, from a write on the way)
            print(f"contoursim: error: cannot write to standard output: {exc.strerror}; the files written are "
                  "complete", file=sys.stderr, flush=True)
        code = 2
    os._exit(code)


if __name__ == "__main__":
    run()
