"""Diagnose a real axis: the EMPS ball-screw drive, whose nominal model lacks friction; validate on a second experiment.

The EMPS benchmark (Janot, Gautier, Brunot, 2019; ../shared/data/real/emps)
logged the commanded (qg) and measured (qm) position of a ball-screw axis
under a documented P position / P velocity loop. This example converts
DATA_EMPS.mat to the measured-trace CSV (``t``, ``x_ref`` = qg, ``x`` = qm,
in mm; ``x_current`` = the drive input vir) in its output folder and runs
the diagnosis against the documented nominal loop, ``emps_axis.toml`` (no
friction in it; the drive's velocity from the 2-tap filtered encoder
position by a backward difference), writing the corrected model — what

    contoursim diagnose OUT/emps.csv --model examples/emps/emps_axis.toml --report OUT/emps_report.json --out OUT

does. The benchmark's reference friction (Simulation_EMPS.m): Coulomb
Fc = 20.39 N and a constant offset of −3.16 N in its equation
``M·q'' + Fv·q' + Fc·sign(q') + offset = force``, i.e. a constant force of
+3.16 N on the carriage: ``offset_N`` = +3.16 N in contoursim's convention.

Then the benchmark's validation experiment, DATA_EMPS_PULSES.mat: the same
kind of motion with force pulses injected into the drive after the
controller (``vir`` = control law + 1.014·pulses_N, PROVENANCE.md), i.e. a
known force ``x_force`` = gtau·1.014·pulses_N [N] on the carriage, positive
pushing towards +q (the drive's force is gtau·vir). The corrected model of
DATA_EMPS simulates it with that force as an input (identify on one
experiment, validate on the other), and the residual RMS over the whole
record is printed — what

    contoursim diagnose OUT/emps_pulses.csv --model OUT/corrected_model.toml

starts from (its nominal model's residual). In that trace ``x_current`` is
the controller's part of vir (vir − 1.014·pulses_N): the pulses are the force
column, not the loop's command.

Run from a checkout that has ../shared beside it:  python examples/emps/diagnose_emps.py [OUT_DIR]
"""

import sys
from pathlib import Path

import numpy as np
import scipy.io

from contoursim.diagnosis import diagnose, save_figures
from contoursim.model import load_model
from contoursim.output import output_dir
from contoursim.simulation import simulate
from contoursim.traces import Trace, read_trace, write_trace

HERE = Path(__file__).resolve().parent
FOLDER = HERE.parents[2] / "shared" / "data" / "real" / "emps"
DATA, PULSES = FOLDER / "DATA_EMPS.mat", FOLDER / "DATA_EMPS_PULSES.mat"
REFERENCE_FORCE_N, REFERENCE_OFFSET_N = 20.39, 3.16  # Fc, and −offset of the benchmark's equation
PULSE_GAIN = 1.014  # drive input [V] per unit of pulses_N (PROVENANCE.md: vir = control law + 1.014·pulses_N)
VALIDATION_TARGET_UM = 2.5  # issue 18: the residual RMS over the whole PULSES record, identified on DATA_EMPS


def convert(mat, out, name="emps.csv"):
    """Write an EMPS .mat file as the trace CSV `name` [s, mm, N, V] into the output folder `out`; returns its path.

    With ``pulses_N`` (DATA_EMPS_PULSES) the trace gets ``x_force`` = gtau·1.014·pulses_N [N] and ``x_current`` the
    controller's part of the drive input; without, ``x_current`` = vir. The drive input is in V: read as A with
    emps_axis.toml, whose force constant is the drive gain gtau [N/V].
    """
    d = scipy.io.loadmat(mat, squeeze_me=True)
    pulses = d.get("pulses_N")
    metadata = {"source": f"EMPS benchmark {Path(mat).name} (Janot, Gautier, Brunot 2019)", "x": "motor encoder qm",
                "x_current": "drive input vir [V]" + ("" if pulses is None else " less the pulses, 1.014·pulses_N")}
    force, drive = {}, d["vir"]
    if pulses is not None:
        force = {"x": d["gtau"] * PULSE_GAIN * pulses}
        drive = drive - PULSE_GAIN * pulses
        metadata["x_force"] = "injected pulses, gtau·1.014·pulses_N [N]"
    trace = Trace(d["t"], 1e3 * d["qg"][:, None], 1e3 * d["qm"][:, None], ("x",), metadata,
                  force=force, current={"x": drive})
    with out.write(name) as stream:
        write_trace(stream, trace)
    return out.path / name


def validation_rms_um(model, trace):
    """RMS over the whole record of the measured minus simulated position of `model` on `trace` (its force in) [µm]."""
    simulated = simulate(model, trace, contour=False).tool_position
    return 1e3 * float(np.sqrt(np.mean((trace.actual - simulated) ** 2)))


def main(out=Path("contoursim-out"), data=DATA, pulses=PULSES):
    for mat in (data, pulses):
        if not Path(mat).exists():
            raise SystemExit(f"the EMPS data is not at {mat}: it ships beside the repository, not in it")
    out = output_dir(out)
    trace = read_trace(convert(data, out))
    result = diagnose(trace, load_model(HERE / "emps_axis.toml"), progress=lambda line: print(line, file=sys.stderr))
    print(result.report())
    with out.write("emps_report.json") as stream:
        stream.write(result.to_json() + "\n")
    with out.write("corrected_model.toml") as stream:
        stream.write(result.corrected_model())
    save_figures(result, out)
    friction = next((e for e in result.effects if e.name == "coulomb_friction"), None)
    if friction is not None:
        print(f"coulomb_friction.x: force_N = {friction['force_N']:.2f} N (benchmark {REFERENCE_FORCE_N} N, "
              f"{100 * (friction['force_N'] / REFERENCE_FORCE_N - 1):+.1f} %), offset_N = {friction['offset_N']:.2f} N "
              f"(benchmark {REFERENCE_OFFSET_N} N)")

    validation = read_trace(convert(pulses, out, "emps_pulses.csv"))
    corrected = load_model(out.path / "corrected_model.toml")
    rms = validation_rms_um(corrected, validation)
    unforced = validation_rms_um(corrected, Trace(validation.t, validation.reference, validation.actual, ("x",)))
    print(f"validation on DATA_EMPS_PULSES (the corrected model of DATA_EMPS, the pulses as a force input): residual "
          f"{rms:.3f} µm RMS over the whole record (target <= {VALIDATION_TARGET_UM} µm; without the force input "
          f"{unforced:.3f} µm)")
    print(f"written to {out}/: emps.csv, emps_report.json, corrected_model.toml, emps_pulses.csv and the figures")
    return result


if __name__ == "__main__":
    main(*(Path(a) for a in sys.argv[1:2]))
