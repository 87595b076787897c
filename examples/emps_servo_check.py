"""Check the servo model against a real axis: the EMPS ball-screw drive.

The EMPS benchmark (Janot, Gautier, Brunot, 2019; ../shared/data/real/emps)
logged the commanded and measured position of a ball-screw axis under a
documented P position / P velocity loop. Here that loop is rebuilt from the
documented parameters alone — no fitting — and simulated on the measured
run itself: the logged command is the reference of ``simulate`` (a
measured reference: no settle time, no at-rest requirement). The simulated following error is compared with the measured one;
what is left (about 3 % of it) is what the nominal model leaves out; the
data's provenance notes fit it with a ≈0.02 mm sign(v) term, i.e. friction.

Run from a checkout that has ../shared beside it:  python examples/emps_servo_check.py
"""

from pathlib import Path

import numpy as np
import scipy.io

from contoursim.machine import Machine
from contoursim.servo import AxisServo
from contoursim.simulation import simulate
from contoursim.traces import Trace

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "emps" / "DATA_EMPS.mat"


def compare(file=DATA):
    """Simulated and measured following error of the EMPS axis [mm], shape (N,) each."""
    d = scipy.io.loadmat(file, squeeze_me=True)
    dt = float(np.median(np.diff(d["t"])))
    trace = Trace(d["t"], 1e3 * d["qg"][:, None], 1e3 * d["qm"][:, None], ("x",))  # [m] -> [mm]
    axis = AxisServo(
        mass=95.11,                       # [kg]    Simulation_EMPS.m
        damping=203.5,                    # [N·s/m] viscous friction
        force_constant=float(d["gtau"]),  # [N/V]   drive gain: the controller output is a voltage
        kv=float(d["kv"]),                # [V·s/m] velocity gain
        kp=float(d["kp"]),                # [1/s]   position gain
        current_limit=10.0,               # [V]     ±10 V drive input
        velocity_feedback="difference",   # velocity: backward difference of the encoder position ...
        velocity_taps=2,                  # ... after the 2-tap FIR 0.5/0.5
    )
    result = simulate(Machine({"x": axis}, dt), trace)  # no feedforward: the reference's v and a go unused
    return -result.tracking_error[:, 0], -trace.tracking_error[:, 0]


def main(file=DATA):
    """Print the measured and simulated following error of the EMPS axis (data file `file`)."""
    if not Path(file).exists():
        raise SystemExit(f"the EMPS data is not at {file}: it ships beside the repository, not in it")
    simulated, measured = compare(file)
    rms = lambda x: float(np.sqrt(np.mean(x**2)))  # noqa: E731
    print(f"following error RMS, measured : {rms(measured):.4f} mm")
    print(f"following error RMS, simulated: {rms(simulated):.4f} mm")
    print(f"RMS of the difference         : {1e3 * rms(simulated - measured):.1f} µm (not in the nominal model)")


if __name__ == "__main__":
    main()
