"""Diagnose real traces without a nominal model: the TU/e motion rig and the U. Michigan CNC mill.

Both data sets ship beside the repository (../shared/data/real, see their
PROVENANCE.md); the loops are identified from each trace
(:func:`contoursim.identify.identify_machine`), as a user who does not know
the drive's parameters would run ``contoursim diagnose trace.csv``.

- TU/e SPERTE rig (one rotary axis, logged at 4 kHz, taken every 4th sample:
  1 kHz; radians written as the trace's mm, so µm read as µrad): the same
  point-to-point move with feedback only (``no_action``) and with a Coulomb
  friction feedforward (``Kfc_only``). A P/P cascade is only an
  approximation of the rig's loop-shaped controller.
- U. Michigan CNC mill (X, Y, Z, 10 Hz, positions logged with 3 significant
  digits: 1 mm steps above 100 mm, 0.1 mm below), experiment 04.

Each run is converted to the trace CSV in the output folder, diagnosed, and
summarised in one line: what was named, residual RMS before and after, noise floor.

python examples/diagnose_real_traces.py [OUT_DIR]
"""

import csv
import sys
from pathlib import Path

import numpy as np
import scipy.io

from contoursim.diagnosis import diagnose
from contoursim.output import output_dir
from contoursim.traces import Trace, read_trace, write_trace

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def tue(data, name, every=4):
    """A TU/e feedforward run as a one-axis trace [s, rad as mm]."""
    d = scipy.io.loadmat(data / "tue_sperte_motion_setup" / "feedforward" / f"{name}.mat", squeeze_me=True)
    reference, error = (np.asarray(d[k], float).ravel() for k in ("reference", "error"))
    t = np.arange(reference.size) / 4000.0
    keep = slice(None, None, every)
    return Trace(t[keep], reference[keep, None], (reference - error)[keep, None], ("x",),
                 {"source": f"TU/e SPERTE feedforward/{name}.mat, every {every}th sample",
                  "positions": "the stage's rad, written as mm"})


def umich(data, experiment):
    """A U. Michigan experiment as a three-axis trace [s, mm] (10 Hz, no time column: row × 0.1 s)."""
    with open(data / "umich_cnc_mill" / f"experiment_{experiment}.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    column = lambda key: np.array([float(r[key]) for r in rows])  # noqa: E731
    reference = np.column_stack([column(f"{a}1_CommandPosition") for a in "XYZ"])
    actual = np.column_stack([column(f"{a}1_ActualPosition") for a in "XYZ"])
    return Trace(np.arange(len(rows)) * 0.1, reference, actual, ("x", "y", "z"),
                 {"source": f"U. Michigan CNC mill experiment_{experiment}.csv"})


RUNS = {
    "tue_no_action": lambda data: tue(data, "no_action"),
    "tue_coulomb_feedforward": lambda data: tue(data, "Kfc_only(0.0047124)"),
    "umich_experiment_04": lambda data: umich(data, "04"),
}


def report_keys(effect):
    """The parameters of `effect` that differ from their defaults."""
    return [p.name for p, default in zip(effect.parameters, effect.kind.parameters) if p.value != default.value]


def main(out=Path("contoursim-out"), data=DATA):
    if not Path(data).is_dir():
        raise SystemExit(f"the measured data is not at {data}: it ships beside the repository, not in it")
    data = Path(data)
    out = output_dir(out)
    results = {}
    for name, load in RUNS.items():
        with out.write(f"{name}.csv") as stream:
            write_trace(stream, load(data))
        result = diagnose(read_trace(out.path / f"{name}.csv"))
        report = result.to_dict()
        named = ", ".join(f"{e.label} ({', '.join(f'{k} = {e[k]:.3g}' for k in report_keys(e))})"
                          for e in result.effects) or "nothing"
        print(f"{name}: named {named}; residual RMS {report['residual_rms_before_um']:.1f} -> "
              f"{report['residual_rms_after_um']:.1f} µm, noise floor {np.linalg.norm(result.noise_um):.3g} µm")
        results[name] = result
    return results


if __name__ == "__main__":
    main(*(Path(a) for a in sys.argv[1:2]))
