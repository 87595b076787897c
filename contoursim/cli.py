"""Command line: ``contoursim demo | simulate | compare | volumetric | diagnose``.

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
import sys
import warnings
from dataclasses import replace
from pathlib import Path

from .config import TomlFile
from .exceptions import ConfigError, ContoursimWarning, OutputError, UnstableLoopError
from .output import output_dir

DEMO_MACHINE = "demo_mill"
DEMO_STRATEGIES = ("feedforward", "ccc_arc", "feedforward+ccc_arc")  # the demo's compact comparison, on its free-form run
DEMO_RUNS = {"iso230_4_circle": ("iso230_4_circle_ccw.toml", "iso230_4_circle_cw.toml"), "butterfly": ("butterfly.toml",)}
_JOB_KEYS = ("machine", "path", "feed", "work_offset", "geometric_compensation", "effect")


_COLUMNS = {"tracking max": "tracking_max_um", "tracking RMS": "tracking_rms_um", "contour max": "contour_max_um",
            "contour RMS": "contour_rms_um", "volumetric max": "volumetric_max_um"}


def _table(rows):
    """The summary table [µm], one row per run."""
    lines = [f"{'run [µm]':<36}" + "".join(f"{label:>16}" for label in _COLUMNS)]
    lines.append("-" * len(lines[0]))
    for name, summary in rows:
        lines.append(f"{name:<36}" + "".join(f"{summary[key]:>16.2f}" for key in _COLUMNS.values()))
    return "\n".join(lines)


def _trajectory(model, path_file, job=None):
    """The path file's reference at the model's servo period; a job's ``[feed]`` overrides the file's key by key."""
    from .feed import sample
    from .model import as_model
    from .pathfile import library_file, load_path_file, read_feed_table

    path, settings = load_path_file(path_file)
    source = library_file(path_file)
    if job is not None and "feed" in job.data:
        settings = read_feed_table(job, base=settings)
        source = job.source if "feed_mm_min" in job.data["feed"] else source
    machine = as_model(model).machine
    try:
        return sample(path, settings.plan(path, max_feed=machine.max_feed), machine.servo_period)
    except ConfigError:
        raise
    except ValueError as exc:  # a feed above the machine's max feed, a run too large for the memory: naming the file
        raise ConfigError(str(exc), str(source)) from None


def _check_memory(samples, dt, path_file, runs, advice):
    """Refuse `runs` runs of `samples` samples each (a path file's, settling included) that would not fit in memory."""
    from ._memory import check

    check(samples, f"{Path(path_file).name} runs for {samples * dt:.6g} s: at dt = {dt:.6g} s", advice, runs=runs)


def run_job(model, path_file, job=None, strategies=(), label=None, runs=1):
    """Simulate `model` (a Model, or a Machine without effects) on a path file.

    A job file's ``[feed]`` table, when given, overrides the path file's key by key.
    `runs` is the number of such runs the command will hold at once: refused
    before this one starts when they would not fit in the memory available.

    Returns
    -------
    tuple
        ``(name, path_file, result)``: the run's name (file stem or `label`),
        the path file and the :class:`~contoursim.simulation.SimResult`.
    """
    from .model import as_model
    from .simulation import default_settle, simulate

    # held here as simulate would hold it, so that the reference before holding is freed before the run
    trajectory = _trajectory(model, path_file, job).held(default_settle(as_model(model).machine))
    if runs > 1:  # one run is checked when the reference is sampled
        _check_memory(len(trajectory), trajectory.dt, path_file, runs, "run without geometric compensation, or a shorter path")
    name = label or Path(path_file).stem
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContoursimWarning)
        result = simulate(model, trajectory, strategies, settle=0.0)  # held already
    for warning in caught:  # say which run
        warnings.warn(f"{name}: {warning.message}", warning.category, stacklevel=2)
    return name, path_file, result


def _write(out, groups, every):
    """Write each run's trace CSV (every `every`-th sample) and the plots of each group of runs shown side by side.

    Parameters
    ----------
    groups : dict of str -> list of tuple
        Runs (from :func:`run_job`) that share plots, by the group's file stem.

    Returns
    -------
    tuple
        The output folder and the table rows.
    """
    from .plotting import save_figures

    out = output_dir(out)
    for name, runs in groups.items():
        for run, path_file, result in runs:
            with out.write(f"{run}.csv") as stream:
                result.save_csv(stream, metadata={"path": Path(path_file).name}, every=every)
        save_figures({run: result for run, _, result in runs}, out, name)
    return out, [(run, result.summary()) for runs in groups.values() for run, _, result in runs]


def demo(args):
    """The README's main job: ISO 230-4 circles (CCW and CW, plotted together) and a free-form path on the demo machine."""
    from .comparison import Comparison
    from .compensation import strategies_named
    from .machine import load_machine
    from .pathfile import library_file
    from .simulation import simulate

    machine = load_machine(DEMO_MACHINE)
    groups = {name: [run_job(machine, library_file(f)) for f in files] for name, files in DEMO_RUNS.items()}
    (_, free_form, plain), = groups["butterfly"]
    compared = {"none": plain}
    compared.update((name, simulate(machine, plain.trajectory, strategies_named(name), settle=0.0))
                    for name in DEMO_STRATEGIES)  # on the same reference, already held at its end
    out, rows = _write(args.out, groups, args.every)
    print(f"contoursim demo — machine: {machine.name}, servo period {1e3 * machine.servo_period:g} ms")
    print("Tracking error is the lag behind the interpolator (≈ v/Kp); contour error is the distance to the path.")
    print("Both over the test proper: the full test circle of the ISO 230-4 runs (the CSV's measuring = 1 rows).")
    print(_table(rows))
    print(f"\nCompensation strategies on {Path(free_form).stem} (all of them, with plots: contoursim compare {Path(free_form).stem}):")
    print(Comparison(compared).table())
    print(f"\nplots and traces written to {out}/")


def _job(args):
    """Model, path file, job file (or None) and geometric switch of ``simulate FILE``.

    FILE is a job file (a TOML with ``machine`` and ``path`` keys, both naming
    presets/library entries or files relative to the job, and optionally a
    ``[feed]`` table, ``work_offset``, ``geometric_compensation`` and
    ``[[effect]]`` tables, added to the machine file's) or a bare path file, run
    on ``--machine`` (default: the demo machine). A job file names its
    machine, so ``--machine`` with a job file is an error.
    """
    from .machine import read_work_offset
    from .model import load_model, with_file_effects
    from .pathfile import library_file

    file = Path(args.file)
    if file.suffix == ".toml" and file.exists():
        job = TomlFile.read(file)
        if job.kind() == "job":
            if "machine" not in job.data:
                raise job.error('a job file names its machine: add machine = "<preset name or machine file>" '
                                '(e.g. "demo_mill"), or give a path file')
            data = job.table(allowed=_JOB_KEYS, required=("machine", "path"))
            for key in ("machine", "path"):
                if not isinstance(data[key], str):
                    raise job.error(f"{key} must be a name or a file name in quotes, got {data[key]!r}", key)
            if args.machine is not None:
                raise job.error(f"--machine {args.machine} is not used with a job file, which names its machine "
                                f"({data['machine']!r}); drop one of them", "machine")
            near = lambda name: file.parent / name if (file.parent / name).exists() else name  # noqa: E731
            geometric = data.get("geometric_compensation", False)
            if not isinstance(geometric, bool):
                raise job.error(f"geometric_compensation must be true or false, got {geometric!r}", "geometric_compensation")
            model = load_model(near(data["machine"]))
            machine = model.machine
            if "work_offset" in data:
                machine = replace(machine, work_offset={**machine.work_offset, **read_work_offset(job, machine.chain)})
            model = with_file_effects(replace(model, machine=machine), job)
            return model, library_file(near(data["path"])), job, geometric
    return load_model(args.machine or DEMO_MACHINE), library_file(args.file), None, False


def simulate_command(args):
    """``contoursim simulate FILE``: see :func:`_job`. Nothing is written unless every run succeeds."""
    from .geocomp import GeometricCompensation

    model, path_file, job, geometric = _job(args)
    machine = model.machine
    if (geometric or args.geometric_compensation) and machine.chain is None:
        raise ConfigError(f"{machine.name} has no geometric model to compensate with")
    runs = [run_job(model, path_file, job, runs=2 if geometric or args.geometric_compensation else 1)]
    if geometric or args.geometric_compensation:
        runs.append(run_job(model, path_file, job, [GeometricCompensation(machine.chain)],
                            label=f"{Path(path_file).stem}_geometric_comp"))
    out, rows = _write(args.out, {Path(path_file).stem: runs}, args.every)
    effects = "; ".join(f"{e.label} ({_set_values(e)})" for e in model.effects) or "none"
    print(f"contoursim simulate — machine: {machine.name}, path: {Path(path_file).name}, effects: {effects}")
    print(_table(rows))
    print(f"\nplots and traces written to {out}/")


def _set_values(effect):
    """``name = value`` of an effect's size and of every parameter or option not at its default."""
    kind = effect.kind
    values = [f"{p.name} = {p.value:g}" for i, (p, default) in enumerate(zip(effect.parameters, kind.parameters))
              if i == 0 or p.value != default.value]  # fmt: skip
    values += [f"{key} = {effect.options[key]!r}" for key, allowed in kind.options.items()
               if effect.options[key] != (allowed[0] if isinstance(allowed, tuple) else 0)]  # fmt: skip
    return ", ".join(values)


def compare_command(args):
    """``contoursim compare FILE [--strategies a,b] [--json R.json]``: compensation strategies side by side."""
    from .comparison import compare
    from .compensation import STRATEGY_NAMES
    from .output import atomic_write, report_file
    from .plotting import save_comparison_figures
    from .simulation import default_settle

    model, path_file, job, geometric = _job(args)
    if geometric:
        raise job.error("compare runs the strategies of --strategies: compose geometric compensation there "
                        "(e.g. --strategies none,geometric,geometric+ccc_arc)", "geometric_compensation")
    names = STRATEGY_NAMES if args.strategies is None else [n.strip() for n in args.strategies.split(",") if n.strip()]
    report = report_file(args.json, "runs", "comparison JSON")  # never a file the user keeps
    trajectory, dt = _trajectory(model, path_file, job), model.machine.servo_period
    _check_memory(len(trajectory) + math.ceil(default_settle(model.machine) / dt), dt, path_file, len(names),
                  "compare fewer strategies (--strategies) or a shorter path")
    comparison = compare(model, trajectory, names)
    out = output_dir(args.out)
    save_comparison_figures(comparison, out, Path(path_file).stem)
    if report is not None:  # the files before the table: a reader gone half-way (| head) costs none of them
        with atomic_write(report) as stream:
            stream.write(comparison.to_json() + "\n")
    machine = comparison.runs[names[0]].machine
    print(f"contoursim compare — machine: {machine.name}, path: {Path(path_file).name}; errors over the test proper")
    print(comparison.table())
    if report is not None:
        print(f"\ncomparison written to {report}")
    print(f"plots written to {out}/")


def volumetric(args):
    """``contoursim volumetric MACHINE``: worst volumetric errors and error-field plots."""
    from .machine import preset_file
    from .volumetric import volumetric_report

    print(volumetric_report(preset_file(args.machine), args.out))


def diagnose_command(args):
    """``contoursim diagnose MEASURED.csv [--model M.toml] [--report R.json]``: name what the nominal model lacks."""
    from ._memory import DIAGNOSIS_BYTES_PER_SAMPLE, check
    from .diagnosis import diagnose, save_figures
    from .identify import servo_period_for
    from .model import load_model
    from .output import report_file, writing
    from .traces import read_trace

    trace = read_trace(args.file)
    model = load_model(args.model) if args.model else None
    period = model.machine.servo_period if model is not None else servo_period_for(trace.dt)
    duration = trace.t[-1] - trace.t[0]
    check(int(duration / period) + 1, f"{args.file}: the trace lasts {duration:.6g} s: every servo period of {period:.6g} s",
          "check the unit of the trace's time column (e.g. a line '# units: t [ms]') and the servo period",
          per_sample=DIAGNOSIS_BYTES_PER_SAMPLE)
    report = report_file(args.report, "residual_rms_before_um", "diagnosis report")  # never a file the user keeps
    print(f"contoursim diagnose — {Path(args.file).name}: axes {', '.join(trace.axes)}, {trace.t.size} samples every "
          f"{1e3 * trace.dt:.4g} ms; nominal model: {args.model or 'identified from the trace'}", flush=True)
    try:
        result = diagnose(trace, model, progress=lambda line: print(line, file=sys.stderr, flush=True))
    except ConfigError:  # naming its own file (the model's)
        raise
    except ValueError as exc:  # what the trace cannot give: naming it
        raise ConfigError(str(exc), args.file) from None
    if report is not None:  # the files before the story: a reader gone half-way (| head) costs none of them
        with writing(report, overwrite=True) as stream:
            stream.write(result.to_json() + "\n")
    save_figures(result, args.out)
    print(result.report())
    if report is not None:
        print(f"report written to {report}")
    print(f"plots written to {args.out}/")


def _every(text):
    """``--every N``: a whole number >= 1."""
    from . import _validate

    try:
        return _validate.positive_int("--every", int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of samples, at least 1; got {text!r}") from None


def main(argv=None):
    """Entry point of the ``contoursim`` command."""
    parser = argparse.ArgumentParser(prog="contoursim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="ISO 230-4 circle tests and a free-form path on the demo machine")
    p.set_defaults(run=demo)
    p = sub.add_parser("simulate", help="simulate a job file (machine + path) or a path file")
    p.add_argument("file", help="job .toml, path .toml or G-code .nc (a file, or a name in the trajectories library)")
    p.add_argument("--machine", help="machine preset or file for a bare path file (default: demo_mill)")
    p.add_argument("--geometric-compensation", action="store_true", help="also run with geometric compensation")
    p.set_defaults(run=simulate_command)
    p = sub.add_parser("compare", help="compensation strategies side by side on a job file or a path file")
    p.add_argument("file", help="job .toml, path .toml or G-code .nc (a file, or a name in the trajectories library)")
    p.add_argument("--machine", help="machine preset or file for a bare path file (default: demo_mill)")
    p.add_argument("--strategies", metavar="A,B,...",
                   help="strategies to run, comma-separated (default: none,feedforward,zpetc,ccc_linear,ccc_arc,"
                        "feedforward+ccc_arc); parts joined by '+' compose, 'geometric' too")
    p.add_argument("--json", metavar="R.json", help="write the comparison (JSON) to this file")
    p.set_defaults(run=compare_command)
    p = sub.add_parser("volumetric", help="volumetric error map of a machine preset or file")
    p.add_argument("machine", help="machine preset name or file")
    p.set_defaults(run=volumetric)
    p = sub.add_parser("diagnose", help="name the effects a nominal model lacks to explain a measured trace")
    p.add_argument("file", help="measured trace CSV (t, x_ref, x[, y_ref, y[, z_ref, z]])")
    p.add_argument("--model", help="nominal machine file or preset (default: identified from the trace)")
    p.add_argument("--report", help="write the diagnosis report (JSON) to this file")
    p.set_defaults(run=diagnose_command)
    for p in sub.choices.values():
        p.add_argument("--out", default="contoursim-out", help="output directory (default: ./contoursim-out)")
    for command in ("demo", "simulate"):
        sub.choices[command].add_argument("--every", type=_every, default=1, metavar="N",
                                          help="write every Nth sample to the trace CSV (default: 1, all, exact to the nm)")
    args = parser.parse_args(argv)

    def show(message, category, filename, lineno, *details):
        if issubclass(category, ContoursimWarning):
            print(f"contoursim {args.command}: warning: {message}", file=sys.stderr)
        else:  # a backstop: one line, saying where (the sources of such warnings are guarded)
            print(f"contoursim {args.command}: warning: {category.__name__}: {message} "
                  f"({Path(filename).name}, line {lineno})", file=sys.stderr)

    try:
        with warnings.catch_warnings():
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


def run():
    """The ``contoursim`` program (and ``python -m contoursim``): :func:`main` tuned for a whole process.

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
      and no traceback; the files completed by then are kept.

    :func:`main` itself leaves the process as it is, for callers in Python.
    """
    gc.set_threshold(10_000, 10, 10)
    try:
        code = main()
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:  # None: started with the descriptor closed (contoursim demo >&-)
                stream.flush()
    except BrokenPipeError:  # the reader of the output is gone (contoursim demo | head): no traceback
        code = 1
    os._exit(code)


if __name__ == "__main__":
    run()
