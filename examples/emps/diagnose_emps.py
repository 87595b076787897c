"""Diagnose a real axis: the EMPS ball-screw drive, whose nominal model lacks friction.

The EMPS benchmark (Janot, Gautier, Brunot, 2019; ../shared/data/real/emps)
logged the commanded (qg) and measured (qm) position of a ball-screw axis
under a documented P position / P velocity loop. This example converts
DATA_EMPS.mat to the measured-trace CSV (``t``, ``x_ref`` = qg, ``x`` = qm,
in mm) in its output folder and runs the diagnosis against the documented
nominal loop, ``emps_axis.toml`` (no friction in it; the drive's velocity
from the 2-tap filtered encoder position by a backward difference) — what

    contoursim diagnose OUT/emps.csv --model examples/emps/emps_axis.toml --report OUT/emps_report.json --out OUT

does. The benchmark's reference friction (Simulation_EMPS.m): Coulomb
Fc = 20.39 N and a constant offset of −3.16 N in its equation
``M·q'' + Fv·q' + Fc·sign(q') + offset = force``, i.e. a constant force of
+3.16 N on the carriage: ``offset_N`` = +3.16 N in contoursim's convention.

Run from a checkout that has ../shared beside it:  python examples/emps/diagnose_emps.py [OUT_DIR]
"""

import sys
from pathlib import Path

import scipy.io

from contoursim.diagnosis import diagnose, save_figures
from contoursim.model import load_model
from contoursim.output import output_dir
from contoursim.traces import Trace, read_trace, write_trace

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[2] / "shared" / "data" / "real" / "emps" / "DATA_EMPS.mat"
REFERENCE_FORCE_N, REFERENCE_OFFSET_N = 20.39, 3.16  # Fc, and −offset of the benchmark's equation


def convert(mat, out, name="emps.csv"):
    """Write DATA_EMPS.mat as the trace CSV `name` [s, mm] into the output folder `out`; returns its path."""
    d = scipy.io.loadmat(mat, squeeze_me=True)
    trace = Trace(d["t"], 1e3 * d["qg"][:, None], 1e3 * d["qm"][:, None], ("x",),
                  {"source": "EMPS benchmark DATA_EMPS.mat (Janot, Gautier, Brunot 2019)", "x": "motor encoder qm"})
    with out.write(name) as stream:
        write_trace(stream, trace)
    return out.path / name


def main(out=Path("contoursim-out"), data=DATA):
    if not Path(data).exists():
        raise SystemExit(f"the EMPS data is not at {data}: it ships beside the repository, not in it")
    out = output_dir(out)
    trace = read_trace(convert(data, out))
    result = diagnose(trace, load_model(HERE / "emps_axis.toml"), progress=lambda line: print(line, file=sys.stderr))
    print(result.report())
    with out.write("emps_report.json") as stream:
        stream.write(result.to_json() + "\n")
    save_figures(result, out)
    friction = next((e for e in result.effects if e.name == "coulomb_friction"), None)
    if friction is not None:
        print(f"coulomb_friction.x: force_N = {friction['force_N']:.2f} N (benchmark {REFERENCE_FORCE_N} N, "
              f"{100 * (friction['force_N'] / REFERENCE_FORCE_N - 1):+.1f} %), offset_N = {friction['offset_N']:.2f} N "
              f"(benchmark {REFERENCE_OFFSET_N} N)")
    print(f"written to {out}/: emps.csv, emps_report.json and the figures")
    return result


if __name__ == "__main__":
    main(*(Path(a) for a in sys.argv[1:2]))
