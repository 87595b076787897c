"""From a measured ISO 230-2 positioning test to an error table in the machine chain.

The ESS target drive unit B02 (../shared/data/real/psi_ess_target_iso230_2)
was driven to 9 (X, Y) or 5 (Z) targets, 5 cycles, approached from both
directions, while a laser-triangulation sensor measured the true position.
This script reads the ``*_ISO230.dat`` files (the ecmc tool's format,
parsed here), recomputes the ISO 230-2 figures with
:mod:`contoursim.iso230_2`, where their definitions are (the tool's own
report.md is not trusted: its direction labels are swapped), writes each
axis's mean bidirectional positional deviation as an error table that
:func:`contoursim.errormotion.read_error_table` reads, builds a one-axis
machine (TOML beside the table) whose axis uses it, and shows that the
chain's positioning error reproduces the measurement at the targets and
interpolates it linearly between them.

In the .dat files ``REF_DATA_FWD`` is the ↑ data: the raw X log shows test
steps 1xxx (written FWD) taken on rising targets after the −20.5 mm
overshoot, and 2xxx (BWD) on falling targets after +20.5 mm. So FWD is the
test's ``up`` and BWD its ``down``.

python examples/iso230_2_error_table.py [OUT_DIR]   (default ./contoursim-out)
"""

import re
import sys
from pathlib import Path

import numpy as np

from contoursim.config import TomlFile
from contoursim.exceptions import ConfigError
from contoursim.output import output_dir
from contoursim.iso230_2 import PositioningTest, positioning_figures, write_error_table
from contoursim.multibody import chain_from_toml

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "psi_ess_target_iso230_2"
FILES = {
    "x": "x__target_x.md_ISO230.dat",
    "y": "y__report_target_y.md_ISO230.dat",
    "z": "z__report_z.md_ISO230.dat",
}
UM_PER_MM = 1e3  # [µm/mm]

_LINE = re.compile(r"^([A-Z][A-Z0-9_]*)(?:\[\s*(\d+)\s*(?:,\s*(\d+)\s*)?\])?=(.*)$")
_ARRAYS = {"TGT_DATA": 1, "REF_DATA_FWD": 2, "REF_DATA_BWD": 2}  # name: number of indices


def _entry(key, index):
    """An indexed entry as the file writes it, e.g. ``REF_DATA_FWD[2,5]``."""
    return f"{key}[{','.join(map(str, index))}]"


def read_iso230_dat(file):
    """Read an ecmc ``*_ISO230.dat`` file (``KEY=VALUE`` lines).

    ``TGT_DATA[i]`` is target i [mm], ``REF_DATA_FWD[i,j]`` and
    ``REF_DATA_BWD[i,j]`` the reference position at target i, cycle j, in the
    positive and negative approach direction [mm]; indices count from 1.
    ``POSITIONS`` and ``CYCLES`` (optional) fix the counts, ``UNIT`` (optional)
    must be ``mm``. Blank lines and ``#`` lines are skipped; other scalar keys
    are kept as text.

    Parameters
    ----------
    file : str or Path
        The .dat file.

    Returns
    -------
    contoursim.iso230_2.PositioningTest
        Targets sorted ascending (with their rows); ``up`` is
        ``REF_DATA_FWD``, ``down`` is ``REF_DATA_BWD``.

    Raises
    ------
    ConfigError
        Naming the file and line of a malformed, repeated or non-numeric
        entry, or the file and the first missing entry.
    """
    source = str(file)
    try:
        lines = Path(file).read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise ConfigError(f"cannot read the ISO 230-2 data: {exc.strerror}", source) from None
    scalars, arrays = {}, {name: {} for name in _ARRAYS}
    for number, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        match = _LINE.match(line)
        if not match:
            raise ConfigError(f"expected KEY=VALUE, TGT_DATA[i]=..., or REF_DATA_FWD|BWD[i,j]=...; got {line[:60]!r}", source, number)
        key, i, j, value = match.groups()
        if i is None:
            if key in _ARRAYS:
                raise ConfigError(f"{key} needs {_ARRAYS[key]} index(es) in brackets", source, number)
            if key in scalars:
                raise ConfigError(f"{key} is given twice (first on line {scalars[key][1]})", source, number)
            scalars[key] = (value.strip(), number)
            continue
        index = (int(i),) if j is None else (int(i), int(j))
        if key not in _ARRAYS or len(index) != _ARRAYS[key]:
            raise ConfigError(f"unknown indexed entry {line.split('=')[0]!r}; expected TGT_DATA[i] or REF_DATA_FWD|BWD[i,j]", source, number)
        if min(index) < 1:
            raise ConfigError(f"{key}: indices count from 1, got {index}", source, number)
        if index in arrays[key]:
            raise ConfigError(f"{_entry(key, index)} is given twice (first on line {arrays[key][index][1]})", source, number)
        try:
            v = float(value)
        except ValueError:
            v = np.nan
        if not np.isfinite(v):
            raise ConfigError(f"{_entry(key, index)}: {value.strip()!r} is not a finite number", source, number)
        arrays[key][index] = (v, number)

    def count(name, default):
        if name not in scalars:
            return default
        text, number = scalars[name]
        if not text.isdigit() or int(text) < 2:
            raise ConfigError(f"{name} must be an integer >= 2, got {text!r}", source, number)
        return int(text)

    if "UNIT" in scalars and scalars["UNIT"][0] != "mm":
        raise ConfigError(f"UNIT must be mm, got {scalars['UNIT'][0]!r}", source, scalars["UNIT"][1])
    m = count("POSITIONS", max((k[0] for k in arrays["TGT_DATA"]), default=0))
    n = count("CYCLES", max((k[1] for k in arrays["REF_DATA_FWD"]), default=0))
    wanted = {"TGT_DATA": [(i,) for i in range(1, m + 1)]}
    wanted["REF_DATA_FWD"] = wanted["REF_DATA_BWD"] = [(i, j) for i in range(1, m + 1) for j in range(1, n + 1)]
    table = {}
    for name, keys in wanted.items():
        extra = sorted(set(arrays[name]) - set(keys))
        if extra:
            raise ConfigError(f"{_entry(name, extra[0])} is beyond {m} positions x {n} cycles", source, arrays[name][extra[0]][1])
        missing = [k for k in keys if k not in arrays[name]]
        if missing or not keys:
            what = _entry(name, missing[0]) if missing else name
            raise ConfigError(f"missing {what} ({m} positions x {n} cycles expected)", source)
        table[name] = np.array([arrays[name][k][0] for k in keys])
    order = np.argsort(table["TGT_DATA"])
    try:
        return PositioningTest(
            table["TGT_DATA"][order],
            up=table["REF_DATA_FWD"].reshape(m, n)[order],
            down=table["REF_DATA_BWD"].reshape(m, n)[order],
        )
    except ValueError as exc:
        raise ConfigError(str(exc), source) from None


def axis_machine(folder, axis, table, travel):
    """Write and load a one-axis machine whose axis carries the tool over a fixed workpiece.

    Parameters
    ----------
    folder : str, Path or contoursim.output.OutputDir
        Where the TOML is written (beside `table`); see :func:`contoursim.output.output_dir`.
    axis : str
        ``"x"``, ``"y"`` or ``"z"``.
    table : str
        The error table's file name, relative to `folder`.
    travel : tuple of float
        Axis travel (min, max) [mm].

    Returns
    -------
    file : Path
        The machine TOML.
    chain : contoursim.multibody.MachineChain
    """
    folder = output_dir(folder)
    file = folder.file(f"{axis}_iso230_2_axis.toml")
    with folder.write(file.name) as stream:
        stream.write(
            f'name = "one-axis {axis.upper()} slide, ISO 230-2 table"\n'
            f'tool = "{axis.upper()}"\n'
            'workpiece = "bed"\n\n'
            "[[body]]\n"
            f'name = "{axis.upper()}"\n'
            'parent = "bed"\n'
            f'joint = "linear {axis}"\n'
            f'axis = "{axis}"\n'
            f"travel_mm = [{travel[0]:g}, {travel[1]:g}]\n"
            "[body.errors]\n"
            f'table = "{table}"                 # measured positioning error d{axis}(q)\n'
        )
    return file, chain_from_toml(TomlFile.read(file))


def positioning_error(chain, q):
    """The chain's tool-tip error along its single axis at positions `q`.

    Parameters
    ----------
    chain : contoursim.multibody.MachineChain
        A one-axis machine.
    q : ndarray, shape (N,)
        Axis positions [mm].

    Returns
    -------
    ndarray, shape (N, 3)
        Volumetric position error [mm] (x, y, z).
    """
    return chain.volumetric_error(np.asarray(q, float)[:, None])[0]


def main(out=Path("contoursim-out"), data=DATA):
    """Print the ISO 230-2 table of X, Y, Z (files in `data`); write error tables and one-axis machines into `out`."""
    if not Path(data).is_dir():
        raise SystemExit(f"the ISO 230-2 data is not at {data}: it ships beside the repository, not in it")
    out = output_dir(out)
    for axis, name in FILES.items():
        figures = positioning_figures(read_iso230_dat(Path(data) / name))
        print(f"\n{axis.upper()} axis ({name}), deviation = measured - target [µm], ↑ = REF_DATA_FWD")
        print(f"{'target mm':>10} {'x̄↑':>8} {'x̄↓':>8} {'x̄':>8} {'B_i':>8} {'R↑_i':>7} {'R↓_i':>7}")
        columns = (figures.mean_up, figures.mean_down, figures.mean_bidirectional, figures.reversal)
        for i, target in enumerate(figures.targets):
            means = " ".join(f"{UM_PER_MM * c[i]:8.1f}" for c in columns)
            print(f"{target:10.1f} {means} {4 * UM_PER_MM * figures.s_up[i]:7.1f} {4 * UM_PER_MM * figures.s_down[i]:7.1f}")
        quoted = {
            "mean reversal B̄": figures.reversal_mean, "reversal B = max|B_i|": figures.reversal_max,
            "systematic E": figures.systematic, "range of x̄ M": figures.mean_range,
            "repeatability R↑": figures.repeatability_up, "repeatability R↓": figures.repeatability_down,
            "repeatability R": figures.repeatability, "accuracy A": figures.accuracy,
            "drift cycle 1→n": figures.drift,
        }
        for label, value in quoted.items():
            print(f"  {label:<24} {UM_PER_MM * value:8.1f} µm")
        table = f"{axis}_iso230_2.csv"
        with out.write(table) as stream:  # replaces only its own file
            write_error_table(stream, axis, figures, source=name)
        travel = (figures.targets[0], figures.targets[-1])
        file, chain = axis_machine(out, axis, table, travel)
        q = np.linspace(*travel, 8 * (figures.targets.size - 1) + 1)  # the targets and 7 points between each pair
        error = positioning_error(chain, q)
        k = "xyz".index(axis)
        gap = np.abs(error[:, k] - np.interp(q, figures.targets, figures.mean_bidirectional)).max()
        off_axis = np.abs(np.delete(error, k, axis=1)).max()
        print(f"  chain {file.name}: |d{axis}(q) - interpolated x̄| <= {UM_PER_MM * gap:.1e} µm "
              f"at {q.size} positions; off-axis error {UM_PER_MM * off_axis:.1e} µm")
    print(f"\nerror tables and machines written to {out}/")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("contoursim-out"))
