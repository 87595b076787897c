"""Sweeps: many variants of one job, one row of figures each; on this machine or on a dask cluster.

A sweep spec is a job file (``machine``, ``path``, optionally ``[feed]``,
``work_offset``, ``[[effect]]``) with the strategies to run, how to draw
the variants and one ``[[vary]]`` table per parameter varied::

    machine = "demo_mill"
    path = "iso230_4_circle_ccw"
    strategies = "ccc_arc"          # a comparison name: parts joined by '+'

    [sweep]
    method = "lhs"                  # "grid", "random" or "lhs" (Latin hypercube)
    count = 200                     # random and lhs: the number of variants
    seed = 1                        # random and lhs: same seed, same variants

    [[vary]]
    name = "strategy.ccc_arc.kp_per_s"
    min = 20.0
    max = 400.0
    log = true                      # optional: uniform in log(value)

    [[vary]]
    name = "effect.backlash.x.lost_motion_um"
    min = 0.0
    max = 20.0
    count = 5                       # grid: count points from min to max, or values = [...]

Parameters are named as the files name them (:data:`PARAMETER_KINDS`):
``axes.<axis>.<key>`` (a machine file's ``[axes.<axis>]`` key,
:data:`contoursim.machine.SERVO_KEYS`), ``effect.<effect>.<axis>.<parameter>``
(an ``[[effect]]`` table's parameter; the effect is added when the job lacks
it) and ``strategy.<strategy>.<key>`` (the ``[[strategy]]`` keys of a job file,
:data:`contoursim.compensation.STRATEGY_KEYS`).

Every variant runs in :func:`contoursim.simulation.simulate_batch` (they all
share the job's structure: varying a parameter never changes the axes, the
servo period or the chain), in tasks of many variants; a task carries only
the job's file texts and the variants' values, and whoever runs it rebuilds
the model (once per process). A variant's row depends on its values alone
(each batch row equals its single run bit for bit), so the table is the
same, bit for bit, however the variants are split into tasks and whichever
worker runs them. With a pre-filter (``zpetc``), designed from each
variant's own servos, the variants run one by one.
"""

import dataclasses
import hashlib
import itertools
import math
import sys
import tempfile
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from . import _validate
from .config import TomlFile, local_file, read_text
from .exceptions import ConfigError
from .simulation import SUMMARY_KEYS

__all__ = ["FIGURES", "METHODS", "PARAMETER_KINDS", "Progress", "Sweep", "best_and_worst", "diverged_why",
           "plot_sweep", "read_sweep", "run_sweep", "run_variants", "table_files", "table_text", "write_results"]

#: How the variants are drawn.
METHODS = ("grid", "random", "lhs")
#: The first part of a varied parameter's name.
PARAMETER_KINDS = ("axes", "effect", "strategy")
#: The figures of each variant, the table's last columns (:data:`contoursim.simulation.SUMMARY_KEYS`).
FIGURES = SUMMARY_KEYS
#: Keys of a spec on top of a job file's.
SPEC_KEYS = ("strategies", "sweep", "vary")
_SWEEP_KEYS = ("method", "count", "seed", "task_size")
_VARY_KEYS = ("name", "min", "max", "count", "values", "log")


@dataclass(frozen=True)
class Sweep:
    """A sweep read from its spec: the job's files and the variants' values.

    Parameters
    ----------
    source : str
        The spec file.
    files : dict of str -> str
        The spec's text (under its file name, the first entry) and the texts
        of the machine and path files it names next to it (and of the error
        tables the machine file names), by path relative to the spec's
        folder: all a worker needs to rebuild the job.
    strategies : str
        The strategies' comparison name (``"none"``, ``"ccc_arc"``, ...).
    names : tuple of str
        The varied parameters.
    values : ndarray, shape (n_variants, len(names))
        One row per variant [each parameter's unit].
    task_size : int or None
        Variants per task (None: chosen by :func:`run_sweep`).
    elsewhere : tuple of str
        Files the job reads that are not in the spec's folder (or below it):
        the sweep runs here, not on a cluster.
    log : tuple of bool
        Per parameter: drawn uniform in log(value) (plotted on a log axis);
        ``()`` for none.

    Raises
    ------
    TypeError
        A name, a flag, the strategies or a file's text of the wrong type;
        `names` a single name.
    ValueError
        `values` not finite or not one column per name, no variant, a name
        given twice, no files, a `task_size` below 1, or `log` not one flag
        per name.
    """

    source: str
    files: dict
    strategies: str
    names: tuple
    values: np.ndarray
    task_size: int | None = None
    elsewhere: tuple = ()
    log: tuple = ()

    def __post_init__(self):
        if not isinstance(self.files, Mapping) or not self.files:
            raise ValueError(f"files must map the spec's file name to its text, first, then the files it names; got "
                             f"{_validate.shown(self.files)}")
        bad = next((name for name, text in self.files.items() if not (isinstance(name, str) and isinstance(text, str))),
                   None)
        if bad is not None:
            raise TypeError(f"files must map file names to their texts (str), got {bad!r}: "
                            f"{_validate.shown(self.files[bad])}")
        if not isinstance(self.strategies, str):
            raise TypeError(f"strategies must be a comparison name (\"ccc_arc\", \"feedforward+ccc_arc\"), got "
                            f"{self.strategies!r}")
        if isinstance(self.names, str):  # its characters would be the names
            raise TypeError(f"names must be a sequence of parameter names, got the single name {self.names!r}: "
                            f"give ({self.names!r},)")
        names = tuple(self.names)
        for i, name in enumerate(names):
            if not isinstance(name, str):
                raise TypeError(f"names[{i}] must be a parameter name (text), got {name!r}")
            if names.index(name) != i:
                raise ValueError(f"names[{i}] {name!r} is varied twice (names[{names.index(name)}]): vary each once")
        values = _validate.finite_array("values", self.values, shape=(None, len(names)))
        if not len(values):
            raise ValueError("values holds no variant: a sweep needs one row or more")
        if self.task_size is not None:
            object.__setattr__(self, "task_size", _validate.positive_int("task_size", self.task_size))
        log = tuple(_validate.flag(f"log[{i}]", v) for i, v in enumerate(self.log)) or (False,) * len(names)
        if len(log) != len(names):
            raise ValueError(f"log must hold one flag per name ({len(names)}), got {len(log)}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "log", log)


def _bundle(file, toml):
    """``(files, elsewhere)``: the text of a sweep's spec or of a machine file (`file`, read as `toml`) and those of
    the files it names in its folder (a machine file's error tables too), by path relative to the folder; and the
    files it names outside it. :func:`_written` writes them into another folder, where the names find them."""
    from .pathfile import NAME_SUFFIXES

    files, elsewhere = {file.name: toml.text}, []
    folder = file.parent.resolve()

    def add(value, base, suffixes=()):
        found = local_file(value, base, suffixes)  # as the job reads it: "demo_mill" is a demo_mill.toml beside it
        found = None if found is None else found.resolve()
        if found is None or not found.is_file():
            if Path(value).is_file():  # relative to the working directory
                elsewhere.append(str(value))
            return None
        if not found.is_relative_to(folder):
            elsewhere.append(str(found))
            return None
        files[found.relative_to(folder).as_posix()] = read_text(found)
        return found

    if toml.kind() != "job":  # a machine file (a fleet's nominal machine): its tables
        machine = file.resolve()
    else:  # a spec: the machine and path files it names, the machine file's tables
        machine = (add(toml.data["machine"], file.parent, (".toml",)) if isinstance(toml.data.get("machine"), str)
                   else None)
        if isinstance(toml.data.get("path"), str):
            add(toml.data["path"], file.parent, NAME_SUFFIXES)
    bodies = None if machine is None else TomlFile.read(machine).data.get("body")
    for body in bodies if isinstance(bodies, list) else ():  # its error tables ([body.errors] table), relative to it
        errors = body.get("errors") if isinstance(body, dict) else None
        if isinstance(errors, dict) and isinstance(errors.get("table"), str):
            add(errors["table"], machine.parent)
    return files, tuple(elsewhere)


def _written(files, folder):
    """Write `files` (:func:`_bundle`'s: texts by path relative to the folder) into `folder`; the first one's path."""
    for name, text in files.items():  # where the names of the first find them
        (Path(folder) / name).parent.mkdir(parents=True, exist_ok=True)
        (Path(folder) / name).write_text(text, encoding="utf-8")
    return Path(folder) / next(iter(files))


def read_sweep(file):
    """Read a sweep spec (module docstring) and draw its variants.

    Parameters
    ----------
    file : str or Path

    Returns
    -------
    Sweep

    Raises
    ------
    ConfigError
        Naming the file and line of a bad key or value, or of a parameter
        the job has no place for (saying which names it has).
    """
    from .machine import _file_names

    file = Path(file)
    toml = TomlFile.read(file)
    if toml.kind() != "job":
        raise toml.error('a sweep spec is a job file: machine = "...", path = "...", then [sweep] and [[vary]] tables')
    files, elsewhere = _bundle(file, toml)
    sweep = toml.table("sweep", allowed=_SWEEP_KEYS, required=("method",))
    method = sweep["method"]
    if method not in METHODS:
        raise toml.error(f"method must be one of {', '.join(METHODS)}, got {method!r}", "sweep", "method")
    varies = toml.data.get("vary")
    if isinstance(varies, dict):  # [vary]: one table, not an array of them
        raise toml.error("[vary] is one table: a sweep's parameters are each a [[vary]] table (double brackets)", "vary")
    if not isinstance(varies, list) or not varies:
        raise toml.error("a sweep needs at least one [[vary]] table: name = \"axes.x.kp_per_s\", min = ..., max = ...")
    tables = [toml.table("vary", i, allowed=_VARY_KEYS, required=("name",)) for i in range(len(varies))]
    names = tuple(t["name"] for t in tables)
    for i, name in enumerate(names):
        if not isinstance(name, str) or names.index(name) != i:
            raise toml.error(f"vary name must be a parameter name, each varied once; got {name!r}", "vary", i, "name")
    count, seed = None, None
    if method != "grid":
        count = _integer(toml, ("sweep", "count"), sweep.get("count"), 1)
        seed = _integer(toml, ("sweep", "seed"), sweep.get("seed", 0), 0)
    for key in ("count", "seed") if method == "grid" else ():  # a grid draws nothing: its points are the vary tables'
        if key in sweep:
            raise toml.error(f"sweep.{key} is for random and lhs draws: a grid's points are each [[vary]] table's "
                             "count or values", "sweep", key)
    task_size = None if "task_size" not in sweep else _integer(toml, ("sweep", "task_size"), sweep["task_size"], 1)
    values = _draw(toml, tables, method, count, seed)
    strategies = toml.data.get("strategies", "none")
    if not isinstance(strategies, str):
        raise toml.error(f"strategies must be a name in quotes (e.g. \"ccc_arc\"), got {strategies!r}", "strategies")
    if "," in strategies:  # compare's list: it read as one unknown strategy 'none,feedforward'
        raise toml.error(f"strategies = {strategies!r}: a sweep runs one composition on every variant, its parts "
                         "joined by '+' (\"feedforward+ccc_arc\"); to set several side by side, sweep each in a spec of "
                         "its own (or compare them on one job: contoursim compare)", "strategies")
    log = tuple(t.get("log", False) is True for t in tables)
    made = Sweep(str(file), files, strategies, names, values, task_size, elsewhere, log)
    job = _job(made)  # the spec's job, every name and the extreme values checked here, not on a worker
    # a draw's range checked by its bounds first: a range the parameter cannot take is said by the value written
    bounds = [() if method == "grid" else (float(t["min"]), float(t["max"])) for t in tables]
    checked = [(*b, values[:, i].min(), values[:, i].max()) for i, b in enumerate(bounds)]
    # Each name's values are checked beside the other names, as a variant sets them all (some are valid only together:
    # an effect's period_mm beside the amplitude_um it is added with, a screw's motor_mass_kg and
    # screw_stiffness_N_per_um), those held at a value of theirs the job takes: a value refused is then its own table's,
    # not that of another beside it. Each is held at the first of its checked values the job takes beside the others
    # held, from the first variant's; one it takes at none is kept at the first variant's value in the first round (its
    # partner's may be the one wrong), then held at none (a name the job has no place for: said at its own table).
    held = dict(zip(names, values[0]))
    for again in range(3):  # the third: the names taken beside the others once such a name is dropped
        for name, candidates in zip(names, checked):
            value = next((v for v in candidates if _takes(job, {**held, name: v})), None)
            if value is not None:
                held[name] = value
            elif again:
                held.pop(name, None)
    for i, (name, table) in enumerate(zip(names, tables)):
        for k, value in enumerate(checked[i]):
            try:
                job.variant({**held, name: value})
            except (TypeError, ValueError) as exc:
                why = ("; its min and max are taken, a value drawn between them not: vary it on a grid with values = "
                       "[...]" if k >= len(bounds[i]) > 0 else "")
                raise toml.error(f"vary {name!r}: {_file_names(exc)}{why}", "vary", i, "name") from None
    return made


def _takes(job, values):
    """Whether `job` makes the variant of `values` (parameter name -> value) without refusing one of them."""
    try:
        job.variant(values)
    except (TypeError, ValueError):
        return False
    return True


def _integer(toml, keys, value, least):
    name = ".".join(k for k in keys if isinstance(k, str))  # vary.count, not the table's index
    if value is None:  # not given (None is no TOML value)
        raise toml.error(f"{name} is missing: give {keys[-1]} = <a whole number, at least {least}>", *keys)
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise toml.error(f"{name} must be a whole number, at least {least}; got {value!r}", *keys)
    return value


def _draw(toml, tables, method, count, seed):
    """The variants' values, shape (n_variants, len(tables)): a full grid, or `count` seeded draws."""
    columns = []
    for i, t in enumerate(tables):
        log = t.get("log", False)
        if not isinstance(log, bool):
            raise toml.error(f"log must be true or false, got {log!r}", "vary", i, "log")
        if "values" in t:
            values = t["values"]
            if method != "grid" or any(k in t for k in ("min", "max", "count")):
                raise toml.error("values = [...] lists a grid's points: use it with method = \"grid\", without min/max/count",
                                 "vary", i, "values")
            if not isinstance(values, list) or not values or not all(_number(v) for v in values):
                raise toml.error(f"values must be a list of numbers, got {values!r}", "vary", i, "values")
            twice = next((v for k, v in enumerate(values) if v in values[:k]), None)  # 2 and 2.0 alike
            if twice is not None:  # the same variants again, each row of them twice in the table
                raise toml.error(f"vary {t['name']!r}: values lists {twice!r} more than once: each would run again; "
                                 "list each value once", "vary", i, "values")
            if log and min(values) <= 0:  # its plot's axis is logarithmic: such a point would not be drawn
                raise toml.error(f"vary {t['name']!r}: log = true plots the values on a log scale, which "
                                 f"{min(values)!r} is not on: give positive values, or log = false", "vary", i, "log")
            columns.append(np.array(values, float))
            continue
        for key in ("min", "max"):
            if not _number(t.get(key)):
                raise toml.error(f"vary {t['name']!r} needs {key} = <number> (or values = [...] in a grid)", "vary", i)
        low, high = float(t["min"]), float(t["max"])
        if high < low or (log and low <= 0):
            raise toml.error(f"vary {t['name']!r}: min must not exceed max" + (" and both be positive (log)" if log else ""),
                             "vary", i, "min")
        if not math.isfinite(high / low if log else high - low):  # the draws between them would be inf or nan
            raise toml.error(f"vary {t['name']!r}: min = {low:g} and max = {high:g} lie too far apart to draw between: "
                             f"their {'ratio' if log else 'difference'} is beyond ±{_validate.FLOAT_MAX:.4g}",
                             "vary", i, "min")
        if method == "grid":
            points = _integer(toml, ("vary", i, "count"), t.get("count"), 1)
            if points == 1 and high > low:  # linspace's one point is min: max would never run
                raise toml.error(f"vary {t['name']!r}: count = 1 is min = {low:g} alone, max = {high:g} never runs: "
                                 "give count = 2 or more, or values = [...]", "vary", i, "count")
            if points > 1 and high == low:  # the same variant `points` times
                raise toml.error(f"vary {t['name']!r}: min = max = {low:g}: count = {points} would run that one value "
                                 f"{points} times; give count = 1, or a max above min", "vary", i, "count")
            columns.append((low, high, log, points))
        elif "count" in t:
            raise toml.error("a vary table's count gives a grid's points: with random or lhs set [sweep] count",
                             "vary", i, "count")
        elif high == low:  # drawn, it varies in no variant (alone: the same variant count times, as a grid's count)
            raise toml.error(f"vary {t['name']!r}: min = max = {low:g}: every variant would draw that one value; set "
                             "it in the job (or its machine file) instead, or give a max above min", "vary", i, "max")
        else:
            columns.append((low, high, log))
    _fits(toml, tables, method, count, columns)
    if method == "grid":
        columns = [c if isinstance(c, np.ndarray) else np.geomspace(*c[:2], c[3]) if c[2] else np.linspace(*c[:2], c[3])
                   for c in columns]
        return np.array(list(itertools.product(*columns)), float)
    rng = np.random.default_rng(seed)
    if method == "random":
        u = rng.random((count, len(columns)))
    else:  # Latin hypercube: each parameter's range cut in `count` strata, one draw in each, strata paired at random
        u = np.column_stack([(rng.permutation(count) + rng.random(count)) / count for _ in columns])
    out = np.empty_like(u)
    for j, (low, high, log) in enumerate(columns):
        out[:, j] = np.exp(np.log(low) + u[:, j] * np.log(high / low)) if log else low + u[:, j] * (high - low)
    return out


def _fits(toml, tables, method, count, columns):
    """Refuse, before anything is drawn, a sweep whose variants' values, table and plots would not fit in memory.

    Named by the option that sets the count: ``sweep.count``, or a grid's largest ``vary.count`` (or ``values``).
    """
    from . import _memory

    if method != "grid":
        key, what = ("sweep", "count"), f"sweep.count = {count}"
    else:
        points = [len(c) if isinstance(c, np.ndarray) else c[3] for c in columns]
        i = int(np.argmax(points))
        key = ("vary", i, "values" if isinstance(columns[i], np.ndarray) else "count")
        what = f"vary.{key[2]} of {tables[i]['name']!r}: a grid of {' x '.join(map(str, points))} points"
        count = math.prod(points)
    try:
        _memory.check_sweep(count, len(tables), what, "sweep fewer variants (or split the sweep into several)")
    except ValueError as exc:
        raise toml.error(str(exc), *key) from None


def _number(value):
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


# ---------------------------------------------------------------------------------------------
# The job, rebuilt from the files in each process


@dataclass(frozen=True)
class _Job:
    """The nominal model, the held reference and the strategies of a sweep, and how to make a variant."""

    model: object
    trajectory: object
    strategies: tuple
    prefilters: bool

    def variant(self, values):
        """``(model, strategies)`` with the named parameters (module docstring) set to `values`."""
        machine = self.model.machine
        axes, fields, effects, gains = dict(machine.axes), {}, {}, {}
        for name, value in values.items():
            kind, _, rest = name.partition(".")
            parts = rest.split(".")
            value = float(value)
            if kind == "axes" and len(parts) == 2:
                field = _servo_field(machine, *parts)
                if isinstance(getattr(axes[parts[0]], field), int) and value.is_integer():
                    value = int(value)  # a count (velocity_taps, computation_delay_periods): a grid's whole numbers
                fields.setdefault(parts[0], {})[field] = value
            elif kind == "effect" and len(parts) == 3:
                effects[name[len("effect.") :]] = value
            elif kind == "strategy" and len(parts) == 2:
                gains.setdefault(parts[0], {})[_gain_field(self.strategies, *parts, value)] = value
            else:
                raise ValueError(f"a parameter name is axes.<axis>.<key>, effect.<effect>.<axis>.<parameter> or "
                                 f"strategy.<strategy>.<gain>, got {name!r}")
        for axis, changed in fields.items():  # at once: a servo checks them together (motor_mass needs screw_stiffness)
            axes[axis] = dataclasses.replace(axes[axis], **changed)
        model = self.model
        if axes != dict(machine.axes):
            model = dataclasses.replace(model, machine=dataclasses.replace(machine, axes=axes))
        present = {e.label for e in model.effects}
        for label in {n.rpartition(".")[0] for n in effects} - present:  # effects the job lacks: added
            from .effects import Effect

            name, axis = label.split(".")
            model = model.with_effect(Effect(name, axis, **{n.rpartition(".")[2]: v for n, v in effects.items()
                                                            if n.rpartition(".")[0] == label}))
        model = model.with_values({n: v for n, v in effects.items() if n.rpartition(".")[0] in present})
        strategies = tuple(dataclasses.replace(s, **gains[s.name]) if s.name in gains else s for s in self.strategies)
        return model, strategies


def diverged_why(sweep, i):
    """Why a variant counts as diverged, in a sentence with the margins that say how far it is: its axes' loop
    check's refusal, else the coupled loop's check or the run's running away, as :func:`simulate` says them.

    Parameters
    ----------
    sweep : Sweep
        The sweep (:func:`read_sweep`).
    i : int
        The variant's row.

    Returns
    -------
    str
    """
    from .exceptions import UnstableLoopError
    from .machine import _file_names
    from .simulation import simulate

    job = _job(sweep)
    model, strategies = job.variant(dict(zip(sweep.names, sweep.values[i])))
    refusal = model.machine.refusal()  # in the names the spec varies (kp_per_s, not kp)
    if refusal:
        return _file_names(refusal)
    try:  # the variant's single run: the coupled loop's check (its margins) or the axis that ran away
        simulate(model, job.trajectory, strategies, settle=0.0)
    except UnstableLoopError as exc:
        return str(exc)
    return "its loops pass their checks and its single run does not diverge; its row in the batch did"


def _servo_field(machine, axis, key):
    from .machine import SERVO_KEYS

    if axis not in machine.axes:
        raise ValueError(f"the machine has no servo axis {axis!r}; its axes: {', '.join(machine.axes)}")
    if key not in SERVO_KEYS:
        raise ValueError(f"no axis key {key!r}{_validate.closest(key, SERVO_KEYS)}; the keys: {', '.join(SERVO_KEYS)}")
    return SERVO_KEYS[key]


def _gain_field(strategies, name, gain, value):
    """The strategy's parameter a varied setting sets, after checking `value` as a [[strategy]] table's (by its key)."""
    from .compensation import STRATEGY_KEYS, strategy_setting

    if name not in [s.name for s in strategies]:
        raise ValueError(f"the sweep runs no strategy {name!r} (strategies = "
                         f"\"{'+'.join(s.name for s in strategies) or 'none'}\")")
    if gain not in STRATEGY_KEYS.get(name, {}):
        known = ", ".join(STRATEGY_KEYS.get(name, {})) or "none"
        raise ValueError(f"strategy {name} has no setting {gain!r}; its settings: {known}")
    strategy_setting(name, gain, value)  # "velocity_fraction must be ...", not the API's "velocity must be ..."
    return STRATEGY_KEYS[name][gain]


_JOBS = {}  # per process: the job of each set of files, by their digest
_BATCH = 32  # most variants run as one batch (the kernel's lanes)
_PROGRESS_SECONDS = 10.0  # in this process the batches double from one variant while they take less than this


def _job(sweep_or_files):
    """The job of a sweep (from its spec file, so that messages name the user's files) or of its files' texts
    (on a worker: written to a temporary folder, read, removed), built once per process."""
    files = sweep_or_files.files if isinstance(sweep_or_files, Sweep) else sweep_or_files
    digest = hashlib.sha256(repr(sorted(files.items())).encode()).hexdigest()
    if digest not in _JOBS:
        if len(_JOBS) >= 4:  # a long-lived worker keeps the last few jobs (a reference may take 100 MB)
            del _JOBS[next(iter(_JOBS))]
        if isinstance(sweep_or_files, Sweep):
            _JOBS[digest] = _build(Path(sweep_or_files.source))
        else:
            with tempfile.TemporaryDirectory(prefix="contoursim-sweep-") as folder:
                _JOBS[digest] = _build(_written(files, folder))
    return _JOBS[digest]


def _build(spec):
    """Read the job of the spec file `spec`: everything a variant needs is in memory afterwards."""
    from . import cli
    from .compensation import Composition, strategies_named
    from .simulation import default_settle

    model, path_file, job, geometric = cli._job(SimpleNamespace(file=str(spec), machine=None, command="sweep"),
                                                extra_keys=SPEC_KEYS)
    if geometric:  # simulate's and compare's second run: a sweep runs one strategy on every variant, the spec's
        raise job.error('a sweep runs its strategies on every variant: name geometric compensation there (strategies = '
                        '"geometric", or e.g. "feedforward+geometric"), not with geometric_compensation = true',
                        "geometric_compensation")
    settings = cli._strategy_settings(job, [job.data.get("strategies", "none")])  # its tables, as compare reads them
    try:
        strategies = strategies_named(job.data.get("strategies", "none"), chain=model.machine.chain, settings=settings)
    except ValueError as exc:
        raise job.error(str(exc), "strategies") from None
    trajectory = cli._trajectory(model, path_file, job)[0].held(default_settle(model.machine))  # every variant: one length
    return _Job(model, trajectory, strategies, Composition(strategies).prefilters)


def run_variants(files, names, rows):
    """Run variants of a sweep's job: the task every worker runs (plain data in, plain data out).

    Parameters
    ----------
    files : dict of str -> str
        :attr:`Sweep.files`.
    names : sequence of str
        The varied parameters.
    rows : sequence of sequence of float
        Each variant's values, in the order of `names`.

    Returns
    -------
    list of list of float
        Per variant the :data:`FIGURES` (``diverged`` as 1.0 or 0.0; a
        diverged variant's other figures NaN). A variant whose servo loops
        the loop check refuses (:func:`contoursim.servo.check`: unstable, too
        poorly damped, too fast for the servo period), which ``simulate``
        would not run, counts as diverged too.

    Raises
    ------
    TypeError
        `rows` holds text or booleans.
    ValueError
        `rows` not one row of ``len(names)`` values per variant (one
        variant's values given flat, ``[40.0]`` for ``[[40.0]]``).
    """
    from .simulation import simulate_batch

    from .cluster import task_threads

    try:  # a variant's values given flat (np.array([40.0])) were iterated as its rows: "'float' is not iterable"
        rows = _validate.float_array("rows", rows, shape=(None, len(names)))
    except ValueError as exc:
        raise ValueError(f"{exc}: a row per variant, its values in the order of names {tuple(names)}") from None
    job = _job(files)
    task_threads()
    variants = [job.variant(dict(zip(names, row))) for row in rows]
    # a variant the loop check refuses is not run: its coupling's gains, designed on its loops, would not exist
    runs = [i for i, (model, _) in enumerate(variants) if model.machine.refusal() is None]
    for i in runs:  # designed coupling gains that its loops do not allow: said of the variant, not of the batch
        model, strategies = variants[i]
        try:
            for strategy in strategies:
                if strategy.kind == "coupling":
                    strategy.settings(model.machine.axes, model.machine.servo_period)
        except ValueError as exc:
            values = ", ".join(f"{name} = {value:g}" for name, value in zip(names, rows[i]))
            raise ValueError(f"the variant {values}: {exc} (in the spec: a [[strategy]] table's kp_per_s and "
                             "ki_per_s2, or vary strategy.<name>.kp_per_s)") from None
    figures = np.full((len(variants), len(FIGURES)), np.nan)
    figures[:, FIGURES.index("diverged")] = 1.0
    groups = [runs] if not job.prefilters else [[i] for i in runs]  # a pre-filter: one by one
    for group in groups if runs else ():
        summary = simulate_batch([variants[i][0] for i in group], job.trajectory, outputs=("summary",),
                                 strategies=[variants[i][1] for i in group], settle=0.0, check=False)["summary"]
        figures[group] = np.column_stack([summary[key].astype(float) for key in FIGURES])
    return figures.tolist()


# ---------------------------------------------------------------------------------------------
# Running


def _sweep(sweep):
    """`sweep`, refused unless it is a :class:`Sweep`."""
    if not isinstance(sweep, Sweep):
        raise TypeError(f"sweep must be a Sweep (read_sweep reads one from its spec), got {type(sweep).__name__}")
    return sweep


def run_sweep(sweep, scheduler=None, progress=None):
    """Run every variant of a sweep; the table of their figures.

    Parameters
    ----------
    sweep : Sweep
    scheduler : None, str or distributed.Client
        ``None``: in this process. ``"local:N"``: a dask ``LocalCluster`` of
        N worker processes on this machine, on the loopback interface only.
        Another string: the address of a dask scheduler
        (``tcp://host:8786``). A ``distributed.Client``: its cluster.
    progress : callable, optional
        Called as ``progress(done, total)`` each time variants finish.

    Returns
    -------
    ndarray, shape (n_variants, len(FIGURES))
        Row i: the figures of variant i (``diverged`` 1.0 or 0.0).

    Raises
    ------
    ValueError
        A bad scheduler; dask.distributed missing (saying how to install it).
    """
    n = len(_sweep(sweep).values)
    table = np.full((n, len(FIGURES)), np.nan)
    report = _validate.callback("progress", progress) or (lambda done, total: None)
    if scheduler is None:
        report(0, n)
        start, size = 0, sweep.task_size or 1
        while start < n:
            rows = slice(start, min(start + size, n))
            began = time.perf_counter()
            table[rows] = run_variants(sweep.files, sweep.names, sweep.values[rows].tolist())
            report(rows.stop, n)
            if not sweep.task_size and time.perf_counter() - began < _PROGRESS_SECONDS:
                size = min(_BATCH, 2 * size)  # doubled while a batch is short: the progress moves, then the lanes fill
            start = rows.stop
        return table
    if sweep.elsewhere:
        raise ValueError(f"{sweep.source} names {sweep.elsewhere[0]}, outside its folder: a cluster's workers get the "
                         "spec's folder only; copy the file next to the spec (or below it)")
    from .cluster import connected, numba_threads, run_tasks

    with connected(scheduler) as client:
        numba_threads(client)
        threads = sum(w["nthreads"] for w in client.scheduler_info()["workers"].values())
        client.run(run_variants, sweep.files, sweep.names, sweep.values[:1].tolist())  # build the job, compile: warm
        report(0, n)
        size = sweep.task_size or max(1, min(_BATCH, math.ceil(n / (4 * threads))))
        parts = [slice(start, min(start + size, n)) for start in range(0, n, size)]
        tasks = [(sweep.files, sweep.names, sweep.values[rows].tolist()) for rows in parts]
        done = 0
        for i, figures in run_tasks(client, run_variants, tasks, "contoursim-sweep"):  # streamed as they finish
            table[parts[i]] = figures
            done += parts[i].stop - parts[i].start
            report(done, n)
    return table


# ---------------------------------------------------------------------------------------------
# Results

_PLOTTED = {"contour_max_um": "contour max [µm]", "contour_rms_um": "contour RMS [µm]",
            "tracking_max_um": "tracking max [µm]", "tracking_rms_um": "tracking RMS [µm]",
            "peak_current_A": "peak current [A]", "saturated": "saturated [fraction]",
            "volumetric_max_um": "volumetric max [µm]", "volumetric_rms_um": "volumetric RMS [µm]"}


def _table(table, sweep=None):
    """`table` as a float array, refused unless it holds a row of :data:`FIGURES` per variant (of `sweep`, given)."""
    rows = None if sweep is None else len(_sweep(sweep).values)
    return _validate.float_array("table", table, shape=(rows, len(FIGURES)))


def table_text(sweep, table):
    """The table as CSV text: ``variant``, the varied values, then :data:`FIGURES` (floats exact, as ``repr``).

    Parameters
    ----------
    sweep : Sweep
    table : ndarray, shape (n_variants, len(FIGURES))
        From :func:`run_sweep`.
    """
    table = _table(table, sweep)
    lines = [",".join(("variant",) + sweep.names + FIGURES)]
    for i, (values, figures) in enumerate(zip(sweep.values, table)):
        cells = [str(i)] + [repr(float(v)) for v in values]
        cells += [str(bool(f)) if key == "diverged" else repr(float(f)) for key, f in zip(FIGURES, figures)]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


def best_and_worst(table):
    """Indices of the variants with the smallest and the largest max contour error, diverged ones left out (or None).

    Parameters
    ----------
    table : ndarray, shape (n_variants, len(FIGURES))
        From :func:`run_sweep`.
    """
    table = _table(table)
    contour = np.where(table[:, FIGURES.index("diverged")] == 0, table[:, FIGURES.index("contour_max_um")], np.nan)
    if np.isnan(contour).all():
        return None
    return int(np.nanargmin(contour)), int(np.nanargmax(contour))


def plot_sweep(sweep, table):
    """Figures of a sweep: each figure against each varied parameter and, for two parameters, a map of each.

    Parameters
    ----------
    sweep : Sweep
    table : ndarray, shape (n_variants, len(FIGURES))
        From :func:`run_sweep`.

    Returns
    -------
    dict of str -> matplotlib.figure.Figure
        ``sweep_<parameter>`` for each parameter, ``sweep_map`` for two.
        Diverged variants are red crosses at the foot of each plot.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = _table(table, sweep)
    ok = table[:, FIGURES.index("diverged")] == 0
    names, figures = _plot_names(sweep), {}
    for j, name in enumerate(sweep.names):
        fig, axes = plt.subplots(2, 4, figsize=(17, 7), layout="constrained")
        x = sweep.values[:, j]
        for ax, (key, label) in zip(axes.flat, _PLOTTED.items()):
            ax.plot(x[ok], table[ok, FIGURES.index(key)], ".", ms=4)
            ax.plot(x[~ok], np.full((~ok).sum(), 0.03), "rx", transform=ax.get_xaxis_transform(),  # at the foot
                    label="diverged" if (~ok).any() else None)
            ax.set(xlabel=name, ylabel=label, xscale="log" if sweep.log[j] else "linear")
            ax.grid(alpha=0.3)
        if (~ok).any():
            axes.flat[0].legend()
        fig.suptitle(f"{Path(sweep.source).name}: {len(x)} variants, strategies {sweep.strategies}")
        figures[names[j]] = fig
    if len(sweep.names) == 2:
        fig, axes = plt.subplots(2, 4, figsize=(19, 8), layout="constrained")
        x, y = sweep.values[:, 0], sweep.values[:, 1]
        for ax, (key, label) in zip(axes.flat, _PLOTTED.items()):
            points = ax.scatter(x[ok], y[ok], c=table[ok, FIGURES.index(key)], s=18, cmap="viridis")
            ax.plot(x[~ok], y[~ok], "rx")
            fig.colorbar(points, ax=ax, label=label)
            ax.set(xlabel=sweep.names[0], ylabel=sweep.names[1], xscale="log" if sweep.log[0] else "linear",
                   yscale="log" if sweep.log[1] else "linear")
        fig.suptitle(f"{Path(sweep.source).name}: each figure over the two parameters (red crosses: diverged)")
        figures[names[-1]] = fig
    return figures


def _plot_names(sweep):
    """The names of :func:`plot_sweep`'s figures: ``sweep_<parameter>`` for each parameter, ``sweep_map`` for two."""
    return [f"sweep_{name}" for name in sweep.names] + (["sweep_map"] if len(sweep.names) == 2 else [])


def _parquet():
    """pyarrow and its Parquet module, or None when pyarrow is not installed (no ``sweep.parquet``)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    return pa, pq


def table_files(sweep):
    """The names of the files :func:`write_results` writes whatever the variants give: the table and its plots.

    ``sweep.csv``, ``sweep.parquet`` when pyarrow is installed, and a PNG of each of :func:`plot_sweep`'s figures;
    those of the best and worst variants depend on the results (whether any variant ran, whether its path is a
    circular test).

    Parameters
    ----------
    sweep : Sweep

    Returns
    -------
    list of str
    """
    return ["sweep.csv", *(["sweep.parquet"] if _parquet() is not None else []),
            *(f"{name}.png" for name in _plot_names(sweep))]


def write_results(sweep, table, out):
    """Write a sweep's table, plots and the best and worst variants re-run with full traces into `out`.

    ``sweep.csv`` (:func:`table_text`), ``sweep.parquet`` when pyarrow is
    installed, the plots of :func:`plot_sweep`, and ``best.csv``,
    ``worst.csv`` with the usual plots of both
    (:func:`contoursim.plotting.save_figures`, polar plot ``best_worst_polar.png``).
    An earlier sweep's files in `out` that this one does not write (the
    plots of other parameters, its best and worst runs when every variant
    here diverged) are removed: what the folder holds is this sweep's. They
    are those its record names as a sweep's
    (:meth:`contoursim.output.OutputDir.written_by`), never another
    command's of a like name (``simulate`` of a path ``sweep_a``: ``sweep_a_path.png``).

    Parameters
    ----------
    sweep : Sweep
    table : ndarray, shape (n_variants, len(FIGURES))
        From :func:`run_sweep`.
    out : str, Path or contoursim.output.OutputDir

    Returns
    -------
    tuple
        The output folder and the indices ``(best, worst)`` (None when every variant diverged).
    """
    import matplotlib.pyplot as plt

    from .output import output_dir
    from .plotting import figure_files, save_figures
    from .simulation import simulate

    table = _table(table, sweep)  # before the folder is made
    out = dataclasses.replace(output_dir(out), by="sweep")  # each file recorded as a sweep's
    parquet = _parquet()
    figures = plot_sweep(sweep, table)
    chosen = best_and_worst(table)
    runs, metadata = {}, {}  # the best and the worst variant re-run, and what their CSVs say of them
    if chosen is not None:
        job = _job(sweep)
        for label, i in zip(("best", "worst"), chosen):
            model, strategies = job.variant(dict(zip(sweep.names, sweep.values[i])))
            with warnings.catch_warnings(record=True) as caught:  # said of the variant they came from
                warnings.simplefilter("always")
                runs[label] = simulate(model, job.trajectory, strategies, settle=0.0)
            for warning in caught:
                warnings.warn(f"the {label} variant, {i}: {warning.message}", warning.category, stacklevel=2)
            metadata[label] = {"sweep": Path(sweep.source).name, "variant": i,
                               "values": "; ".join(f"{n} = {v!r}" for n, v in zip(sweep.names, sweep.values[i].tolist()))}
    written = [*table_files(sweep), *(f"{label}.csv" for label in runs),
               *(figure_files(runs, "best_worst") if runs else [])]
    try:
        for name in written:  # every name refused before any file is written (a user's file of a plot's name)
            out.file(name)
        with out.write("sweep.csv") as stream:
            stream.write(table_text(sweep, table))
        if parquet is not None:
            pa, pq = parquet
            columns = {"variant": np.arange(len(table))}
            columns.update((name, sweep.values[:, j]) for j, name in enumerate(sweep.names))
            columns.update((key, table[:, j].astype(bool) if key == "diverged" else table[:, j])
                           for j, key in enumerate(FIGURES))
            with out.write("sweep.parquet", binary=True) as stream:
                pq.write_table(pa.table(columns), stream)
        for name, fig in figures.items():
            with out.write(f"{name}.png", binary=True) as stream:
                fig.savefig(stream, format="png", dpi=100)
    finally:
        for fig in figures.values():
            plt.close(fig)
    for label, run in runs.items():
        with out.write(f"{label}.csv") as stream:
            run.save_csv(stream, metadata=metadata[label])
    if runs:
        save_figures(runs, out, "best_worst")
    for name in out.written_by("sweep") - set(written):  # an earlier sweep's files this one did not write again
        out.remove(name)
    return out, chosen


#: Seconds between two lines of :class:`Progress` written to a file (not a terminal).
LOG_EVERY = 10.0


class Progress:
    """A one-line progress bar on stderr: ``sweep: [#####.....] 412/1000 variants, 8.1/s, 1.2 min left``.

    Called as ``progress(done, total)``; the rate counts from the first call, when the work starts (a cluster
    is up and warm), and from its ``done``: work done before, a fleet's traces that failed on reading, is not in
    it, and until work is done here the line says no rate and no time left. On a terminal the
    bar is drawn again in place every half second; elsewhere (a log file, a pipe) it is a line of its own every
    :data:`LOG_EVERY` seconds and at the end, not thousands of redrawings on one line. Used as a context
    manager, it ends a line left open (a run interrupted or failed), so that what is said next has a line of
    its own.

    Parameters
    ----------
    label : str
        What leads the line.
    what : str
        What is counted.
    stream : file object, optional
        Default ``sys.stderr``.
    """

    def __init__(self, label="sweep", what="variants", stream=None):
        self.label, self.what, self.stream = label, what, stream or sys.stderr
        self.terminal = getattr(self.stream, "isatty", lambda: False)()  # a caller's stream may have none
        self.start, self.first, self.last = None, None, -1.0  # set by the first call
        self.open = False  # a line written without its end
        self.drawn = 0  # characters of the line drawn last in place, which the next one covers

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.open:
            print(file=self.stream, flush=True)
            self.open = False

    def __call__(self, done, total):
        now = time.monotonic()
        if self.start is None:  # the work starts: the rate counts from here and from what was done before
            self.start, self.first = now, done
        if done < total and now - self.last < (0.5 if self.terminal else LOG_EVERY):
            return
        self.last = now
        bar = "#" * round(20 * done / total) + "." * (20 - round(20 * done / total))
        line = f"{self.label}: [{bar}] {done}/{total} {self.what}"
        if done > self.first:  # work done here: its rate, and the time the rest takes at it
            rate = (done - self.first) / max(now - self.start, 1e-9)
            left = (total - done) / rate
            line += f", {rate:.3g}/s, " + (f"{left / 60:.1f} min left" if left > 60 else f"{left:.0f} s left")
        end = "\n" if done >= total or not self.terminal else ""
        print(f"\r{line:<{self.drawn}}" if self.terminal else line, end=end, file=self.stream, flush=True)
        self.open = not end
        self.drawn = len(line) if self.open else 0
