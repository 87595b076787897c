"""Fleets: many measured traces diagnosed, one report each, and what the fleet has in common.

``contoursim diagnose A.csv B.csv …`` (or a folder of traces) runs
:func:`contoursim.diagnosis.diagnose` on each trace, in this process or as
tasks on a dask cluster (:mod:`contoursim.cluster`): a task carries the
trace's text and the texts of the nominal machine file and of the error
tables it names, as a sweep's task carries its job's files, and the worker
writes them into a folder of its own and reads them as the CLI would: it
needs none of the user's files.
:func:`fleet_summary` says, per effect named (name and
axis), on how many traces it was named and how its parameters are
distributed, in the order of the traces (file names sorted: nightly tests
named by date read as a drift), and which traces failed and why.
"""

import json
import math
import os
import tempfile
import textwrap
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from . import _validate

__all__ = ["SUMMARY_FORM", "SUMMARY_OPTIONAL", "diagnose_fleet", "diagnose_text", "fleet_summary", "plot_fleet",
           "trace_files"]

#: The form of :func:`fleet_summary` (:func:`contoursim.output.has_form`): ``--summary`` replaces only a file of it.
SUMMARY_FORM = {"traces": None, "diagnosed": None, "failed": ("trace", "error"), "nominal": None,
                "effects": ("name", "axis", "count", "traces", "parameters")}
#: The keys :func:`fleet_summary` has besides those of :data:`SUMMARY_FORM` (an earlier version's summary lacks them).
SUMMARY_OPTIONAL = ("unexplained",)


def trace_files(paths):
    """The trace files of the command line: the files given, and each folder's ``*.csv`` (any case) sorted by name.

    A folder's per-block tables of G-code runs (``NAME_blocks.csv``, which ``simulate`` writes beside each trace:
    :data:`contoursim.gcode.BLOCK_COLUMNS`) are no traces and are left out.

    Parameters
    ----------
    paths : sequence of str or Path
        Trace files and folders.

    Raises
    ------
    ValueError
        A path that does not exist, a folder without ``.csv`` files, or a
        trace given twice (itself and in its folder).
    """
    files = []
    for path in map(Path, _names("paths", paths)):
        if path.is_dir():
            found = sorted(p for p in path.iterdir()  # NIGHT_1.CSV too
                           if p.suffix.lower() == ".csv" and not _block_table(p))
            if not found:  # a folder a machine or a night: its subfolders are not searched, which is said
                below = sorted(p.parent.name for p in path.glob("*/*") if p.suffix.lower() == ".csv")
                inside = (f" (its subfolders, not searched, hold {len(below)}: in "
                          f"{', '.join(dict.fromkeys(below))}; name them)" if below else "")
                raise ValueError(f"{path} holds no .csv trace{inside}")
            files += found
        elif path.exists():
            files.append(path)
        else:
            raise ValueError(f"no trace file {path}")
    seen = {}
    for f in files:  # a file named and its folder, or a file twice: one trace, not two with one report file
        first = seen.setdefault(f.resolve(), f)
        if first is not f:
            also = "" if str(first) == str(f) else f" (also as {f})"
            raise ValueError(f"{first} is given twice{also}: name each trace once")
    return files


def _names(name, files):
    """`files` as a list, refused when it is one file name: its characters would be taken for the files ('/' no trace)."""
    if isinstance(files, (str, bytes, os.PathLike)):
        raise TypeError(f"{name} must be a sequence of file names, got the single name {str(files)!r}: give [{str(files)!r}]")
    return list(files)


def _block_table(file):
    """Whether `file` is a G-code run's per-block table (its first line :data:`~contoursim.gcode.BLOCK_COLUMNS`)."""
    from .gcode import BLOCK_COLUMNS

    if not file.is_file():  # a named pipe or a device: opening it could wait for ever; read as a trace, which says why
        return False
    try:
        with open(file, encoding="utf-8", errors="replace") as stream:
            return stream.readline(1000).rstrip("\r\n") == ",".join(BLOCK_COLUMNS)
    except OSError:  # unreadable: read as a trace, whose reading says why
        return False


def diagnose_text(name, text, model=None):
    """Diagnose one trace given as text: the task of a fleet (plain data in, plain data out).

    Parameters
    ----------
    name : str
        The trace's file name (messages name it).
    text : str
        The trace CSV's text.
    model : str, Path or dict of str -> str, optional
        The nominal machine: a preset's name (or a machine file, read where
        it lies), or the files of a machine file: its text under its name,
        first, then those of the error tables it names, by path relative to
        it (as :attr:`contoursim.sweep.Sweep.files`); ``None``: identified
        from each trace.

    Returns
    -------
    dict
        ``trace`` (the name), and either ``report`` (the diagnosis report,
        :meth:`contoursim.diagnosis.Diagnosis.to_dict`) and ``text`` (its
        table), or ``error`` (why the trace could not be diagnosed).

    Raises
    ------
    TypeError
        `model` is none of these.
    """
    from ._memory import check_diagnosis
    from .cluster import task_threads
    from .diagnosis import diagnose
    from .exceptions import ConfigError, UnstableLoopError
    from .model import load_model
    from .sweep import _written
    from .traces import read_trace

    if isinstance(model, os.PathLike):
        model = os.fspath(model)
    if not (model is None or isinstance(model, (str, Mapping))):
        raise TypeError(f"model must be a preset's name, a machine file or its files (a dict of name -> text), got "
                        f"{type(model).__name__}")
    task_threads()
    with tempfile.TemporaryDirectory(prefix="contoursim-fleet-") as folder:
        file = Path(folder) / Path(name).name
        try:
            file.write_text(text, encoding="utf-8")
            nominal = None
            if model is not None:  # the machine's files in a folder of their own, apart from the trace
                machine = model if isinstance(model, str) else _written(model, Path(folder) / "machine")
                nominal = load_model(machine, check=False)  # the trace judges its loops' stability
            trace = read_trace(file)
            check_diagnosis(trace, nominal, str(file))  # a trace too long for the memory: its failure, not the fleet's
            result = diagnose(trace, nominal)
            return {"trace": name, "report": json.loads(result.to_json()), "text": result.report()}
        except (ConfigError, UnstableLoopError, ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError) as exc:
            return {"trace": name, "error": str(exc).replace(str(Path(folder)) + "/", "")}


def diagnose_fleet(files, model=None, scheduler=None, progress=None):
    """Diagnose each trace file; the outcomes in the order of `files`.

    Parameters
    ----------
    files : sequence of str or Path
        Trace CSV files.
    model : str or Path, optional
        Nominal machine preset or file (default: identified from each trace).
    scheduler : None, str or distributed.Client
        As for :func:`contoursim.sweep.run_sweep`: ``None`` runs here.
    progress : callable, optional
        Called as ``progress(done, total)``: first as the work starts (the
        traces that failed on reading counted done), then as each trace is
        diagnosed.

    Returns
    -------
    list of dict
        :func:`diagnose_text` of each trace.

    Raises
    ------
    ConfigError
        `model` is no preset and no machine file, or a file that cannot be read (at its line), before any trace.
    ValueError
        On a cluster, a machine file naming an error table outside its folder (the workers get its folder only).
    """
    from .config import TomlFile, local_file, read_text
    from .exceptions import ConfigError, TraceFormatError
    from .machine import preset_file
    from .model import load_model
    from .sweep import _bundle

    machine = None
    if model is not None:
        file = preset_file(model)  # a preset or a file: refused here, before any trace, when neither
        load_model(file, check=False)  # a file's error said once at its line, not as every trace's failure
        if local_file(model, suffixes=(".toml",)) is None:  # a preset's name: the workers have the preset
            machine = str(model)
        else:  # the user's file (named with or without .toml) and the error tables it names: their texts, as a sweep's
            machine, elsewhere = _bundle(file, TomlFile.read(file))
            if elsewhere and scheduler is not None:
                raise ValueError(f"{file} names {elsewhere[0]}, outside its folder: a cluster's workers get the "
                                 "machine file's folder only; copy the table next to the machine file (or below it)")
            if elsewhere:  # here: the file read where it lies, its tables found where it names them
                machine = str(file.resolve())
    files = _names("files", files)
    outcomes, tasks, todo = [None] * len(files), [], []
    for i, f in enumerate(map(Path, files)):
        try:
            tasks.append((str(f), read_text(f, TraceFormatError), machine))
            todo.append(i)
        except ConfigError as exc:  # a folder, a pipe, not UTF-8: that trace's failure, the others go on
            outcomes[i] = {"trace": str(f), "error": str(exc).replace(str(f), f.name, 1)}  # as diagnose_text names it
    report = _validate.callback("progress", progress) or (lambda done, total: None)
    done = len(files) - len(todo)
    if scheduler is None:
        report(done, len(files))
        results = ((k, diagnose_text(*args)) for k, args in enumerate(tasks))
        for k, outcome in results:
            outcomes[todo[k]] = outcome
            report(done + k + 1, len(files))
        return outcomes
    from .cluster import connected, numba_threads, run_tasks

    with connected(scheduler) as client:
        numba_threads(client)
        report(done, len(files))
        for k, outcome in run_tasks(client, diagnose_text, tasks, "contoursim-diagnose"):  # as they finish
            outcomes[todo[k]] = outcome
            done += 1
            report(done, len(files))
    return outcomes


def _distribution(values):
    v = np.array(values, float)
    return {"values": v.tolist(), "min": float(v.min()), "median": float(np.median(v)), "max": float(v.max()),
            "mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else 0.0}


def fleet_summary(outcomes):
    """What a fleet's diagnoses have in common.

    Parameters
    ----------
    outcomes : list of dict
        From :func:`diagnose_fleet`.

    Returns
    -------
    dict
        ``traces`` (how many), ``diagnosed`` (how many reports), ``failed``
        (``[{"trace", "error"}]``), ``nominal`` (traces explained by the
        nominal model within noise:
        :func:`contoursim.diagnosis.within_noise`), ``unexplained`` (no
        effect named, but more than noise left), and ``effects``: per
        effect label
        ``<name>.<axis>`` its ``name``, ``axis``, ``count`` (traces it was
        named on), ``traces`` (which, in order) and per parameter its
        distribution over those traces (``values`` in trace order, ``min``,
        ``median``, ``max``, ``mean``, ``std``).

    Raises
    ------
    TypeError
        `outcomes` is no list of dicts (one outcome, a file name).
    ValueError
        `outcomes` is empty, or an outcome is not one :func:`diagnose_text` returns.
    """
    from .diagnosis import within_noise

    _outcomes(outcomes)
    effects, nominal, unexplained = {}, [], []
    reports = [o for o in outcomes if "report" in o]
    for o in reports:
        named = o["report"]["effects"]
        if not named:  # what the nominal model explains, or what no catalogue effect does
            r = o["report"]
            explained = within_noise(named, r["unexplained"], r["steps"][-1]["rms_um"], list(r["noise_um"].values()))
            (nominal if explained else unexplained).append(o["trace"])
        for e in named:
            entry = effects.setdefault(f"{e['name']}.{e['axis']}", {"name": e["name"], "axis": e["axis"], "traces": [],
                                                                    "parameters": {}})
            entry["traces"].append(o["trace"])
            for key, value in e["parameters"].items():
                entry["parameters"].setdefault(key, []).append(value)
    for entry in effects.values():
        entry["count"] = len(entry["traces"])
        entry["parameters"] = {k: _distribution(v) for k, v in entry["parameters"].items()}
    return {"traces": len(outcomes), "diagnosed": len(reports),
            "failed": [{"trace": o["trace"], "error": o["error"]} for o in outcomes if "error" in o],
            "nominal": nominal, "unexplained": unexplained,
            "effects": dict(sorted(effects.items(), key=lambda item: -item[1]["count"]))}


#: What a report that names no effect must hold for the summary to tell the nominal model's from the unexplained.
_OF_NOTHING_NAMED = ("noise_um", "steps", "unexplained")


def _outcomes(outcomes):
    """Refuse `outcomes` unless it is a non-empty list of :func:`diagnose_text`'s outcomes (``trace`` and a
    ``report`` holding its ``effects``, or an ``error``): one outcome alone, or a file name, read as several."""
    if not isinstance(outcomes, (list, tuple)):
        raise TypeError(f"outcomes must be a list of diagnose_fleet's outcomes (one dict per trace), got "
                        f"{type(outcomes).__name__}")
    if not outcomes:
        raise ValueError("outcomes is empty: a fleet summary needs the outcome of one trace or more")
    for i, o in enumerate(outcomes):
        if not isinstance(o, Mapping):
            raise TypeError(f"outcomes[{i}] must be a dict (diagnose_text's outcome), got {type(o).__name__}")
        if "trace" not in o or ("report" in o) == ("error" in o):
            raise ValueError(f"outcomes[{i}] must hold 'trace' and either 'report' or 'error' (diagnose_text's "
                             f"outcome), got the keys {list(o)}")
        if "report" in o and not (isinstance(o["report"], Mapping) and "effects" in o["report"]
                                  and (o["report"]["effects"] or all(k in o["report"] for k in _OF_NOTHING_NAMED))):
            raise ValueError(f"outcomes[{i}]['report'] must be a diagnosis report (Diagnosis.to_dict) with its "
                             f"'effects' (where it names none, its {', '.join(map(repr, _OF_NOTHING_NAMED))} too), "
                             f"got {_validate.shown(o['report'])}")


def plot_fleet(summary):
    """The fleet at a glance: on how many traces each effect was named, and its first parameter over the traces.

    Parameters
    ----------
    summary : dict
        From :func:`fleet_summary`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    effects = summary["effects"]
    rows = 1 + math.ceil(len(effects) / 2)  # the counts, then the effects two a row
    fig, axes = plt.subplots(rows, 2, figsize=(12, 3.2 * rows), layout="constrained", squeeze=False)
    ax = axes[0, 0]
    labels = list(effects) + ["failed"]
    ax.barh(labels, [e["count"] for e in effects.values()] + [len(summary["failed"])],
            color=["C0"] * len(effects) + ["C3"])
    ax.set(xlabel=f"traces (of {summary['traces']})", title="effects named")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # whole traces
    ax.invert_yaxis()
    axes[0, 1].axis("off")
    failed = "\n".join(textwrap.fill(f"{Path(f['trace']).name}: {f['error']}", 70, subsequent_indent="    ")
                       for f in summary["failed"][:12])
    axes[0, 1].text(0, 1, f"failed:\n{failed}" if failed else "no trace failed", va="top", fontsize=8,
                    transform=axes[0, 1].transAxes)
    for ax, (label, e) in zip(axes[1:].flat, effects.items()):
        key, dist = next(iter(e["parameters"].items()))
        ax.plot(range(len(dist["values"])), dist["values"], "o-")
        ax.set_xticks(range(len(e["traces"])), [Path(t).stem for t in e["traces"]], rotation=30, fontsize=7)
        ax.set(ylabel=key, title=f"{label}: named on {e['count']} of {summary['traces']} traces")
        ax.grid(alpha=0.3)
    for ax in axes[1:].flat[len(effects) :]:
        ax.axis("off")
    return fig
