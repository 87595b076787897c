"""A backlash in a compliant screw (the kernel's dead zone) against a continuous plant integrated here, and its limits.

The reference shares no code with the kernel: the two masses and the screw's
dead zone written from the physics as force balances in SI units, integrated
over each servo period by scipy's DOP853 (steps of at most dt/20, so that
the contacts' switching is resolved), driven by a sampled P + velocity-PI
cascade written here.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from contoursim.kernel import LoopEffects, pack, run, run_batch
from contoursim.servo import AxisServo

DT = 2.5e-4
MASS, MOTOR, KF, DAMPING = 200.0, 60.0, 60.0, 500.0
KP, KV, TI, VFF = 50.0, 3000.0, 0.01, 1.0


def screw_axis(stiffness, **kw):
    return AxisServo(**{**dict(mass=MASS, force_constant=KF, kv=KV, ti=TI, kp=KP, vff=VFF, damping=DAMPING,
                               motor_mass=MOTOR, screw_stiffness=stiffness), **kw})  # fmt: skip


def sine(n, amplitude=1.0, hz=5.0):
    """Position, velocity, acceleration of ``amplitude·sin(2π·hz·t)`` [mm], sampled at DT, shape (n, 1) each."""
    w = 2 * np.pi * hz
    t = np.arange(n) * DT
    x, v = amplitude * np.sin(w * t)[:, None], amplitude * w * np.cos(w * t)[:, None]
    return x, v, -w * w * x


def continuous_table(servo, backlash_mm, x_ref, v_ref, dt=DT, approach=0):
    """The table position [mm] at the servo instants: the plant with its dead zone, integrated in continuous time.

    Motor side m1 (drive force, the axis's damping while in contact), table m2, joined by the screw's spring k and
    damper c on the stretch beyond ±h/2; with the gap open each mass on its own, damped by its share of the damping.
    The position loop reads the motor or the table (`servo.position_feedback`), the velocity loop the motor
    velocity or the backward difference of the motor position (`servo.velocity_feedback`, one tap, no filter);
    the current command is applied `servo.computation_delay` (0 or 1) periods later. At the start the axis is at rest
    in position, the screw's stretch at the dead zone's edge a last move in the direction `approach` (+1 or -1; 0:
    the stretch zero) left it at.
    """
    m, m1 = servo.mass, servo.motor_mass
    m2, k = m - m1, 1e6 * servo.screw_stiffness
    c = 2 * servo.screw_damping_ratio * np.sqrt(k * m1 * m2 / m)
    half = 0.5e-3 * backlash_mm
    kv = servo.kv  # [A per m/s]

    def rhs(t, s, force):
        xm, vm, xt, vt = s
        stretch = xt - xm
        if abs(stretch) > half:
            f = k * (stretch - np.copysign(half, stretch)) + c * (vt - vm)  # on the motor side, -f on the table
            cm, ct = servo.damping, 0.0
        else:
            f, cm, ct = 0.0, servo.damping * m1 / m, servo.damping * m2 / m
        return [vm, (force - cm * vm + f) / m1, vt, (-f - ct * vt) / m2]

    read = x_ref[0] * 1e-3  # where the loop holds what it reads: the motor, or on a scale the table
    shift = approach * half if servo.position_feedback == "scale" else 0.0
    s = np.array([read + shift, 0.0, read + shift - approach * half, 0.0])
    integral, last, held = 0.0, s[0], 0.0
    table = np.empty(len(x_ref))
    for n in range(len(x_ref)):
        table[n] = s[2] * 1e3
        position = s[2] if servo.position_feedback == "scale" else s[0]
        velocity = (s[0] - last) / dt if servo.velocity_feedback == "difference" else s[1]
        last = s[0]
        e_v = servo.kp * (x_ref[n] * 1e-3 - position) + servo.vff * v_ref[n] * 1e-3 - velocity  # [m/s]
        current = kv * (e_v + (integral + 0.5 * dt * e_v) / servo.ti)  # PI, trapezoidal integral
        integral += dt * e_v
        applied, held = (held, current) if servo.computation_delay else (current, current)
        s = solve_ivp(rhs, (0.0, dt), s, args=(servo.force_constant * applied,), method="DOP853", rtol=1e-10,
                      atol=1e-13, max_step=dt / 20).y[:, -1]  # fmt: skip
    return table


@pytest.mark.parametrize("stiffness", [150.0, 6600.0])  # relative modes of 300 Hz and 2 kHz
def test_screw_backlash_follows_the_continuous_plant(stiffness):
    # The reference agrees with itself at rtol 1e-12 to 1e-4 µm; the kernel times each contact to within a substep
    # (32 per cycle of the screw's mode), measured 0.06-0.09 µm at most on these runs (a mode chosen once per period:
    # 0.4 µm at 300 Hz, 11 µm at 2 kHz). Tolerance: 2 % of the backlash, against an effect of 6-7.5 µm.
    h = 0.01
    servo = screw_axis(stiffness)
    x, v, a = sine(600)
    kernel = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=h)}).position[:, 0]
    reference = continuous_table(servo, h, x[:, 0], v[:, 0])
    without = run([servo], DT, x, v, a).position[:, 0]
    assert np.abs(without - reference).max() > 0.5 * h  # the backlash shows
    assert np.abs(kernel - reference).max() < 0.02 * h


@pytest.mark.parametrize("feedback, approach", [("motor", 1), ("motor", -1), ("scale", 1), ("scale", -1)])
def test_screw_backlash_closed_by_an_approach_follows_the_continuous_plant(feedback, approach):
    """At rest at the start with the play closed by a move either way, read on the motor or on a scale: as the
    continuous plant started so (within 2 % of the backlash, as centred), and not as the play centred."""
    h = 0.01
    servo = screw_axis(150.0, position_feedback=feedback)
    x, v, a = sine(600)
    kernel = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=h, backlash_approach=approach)})
    reference = continuous_table(servo, h, x[:, 0], v[:, 0], approach=approach)
    centred = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=h)}).position[:, 0]
    assert np.abs(kernel.position[:, 0] - reference).max() < 0.02 * h
    assert np.abs(centred - reference).max() > 0.2 * h


@pytest.mark.parametrize("drive", [dict(velocity_feedback="difference", computation_delay=1, kv=1500.0),
                                   dict(position_feedback="scale", velocity_feedback="difference", kv=1500.0)])
def test_screw_backlash_with_the_drive_s_structure_follows_the_continuous_plant(drive):
    # the drive's velocity difference, its computation delay, the loop on the table: the same tolerance (see above),
    # measured 0.10 and 0.15 µm against effects of 6.7 and 9.1 µm
    h = 0.01
    servo = screw_axis(150.0, **drive)
    x, v, a = sine(600)
    kernel = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=h)}).position[:, 0]
    reference = continuous_table(servo, h, x[:, 0], v[:, 0])
    without = run([servo], DT, x, v, a).position[:, 0]
    assert np.abs(without - reference).max() > 0.5 * h
    assert np.abs(kernel - reference).max() < 0.02 * h


def test_vanishing_backlash_is_the_screw_axis():
    # at rest the table starts in the middle of the gap, so the first substep runs open (the drive pushes the motor
    # side alone for dt/M): a start that differs by 12 nm, which the loop forgets; after it the contact holds and the
    # steps are the screw axis's (its period's ZOH as M substeps, the spring offset by 5e-13 mm): to round-off
    servo = screw_axis(150.0)
    x, v, a = sine(4000)
    plain = run([servo], DT, x, v, a)
    tiny = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=1e-12)})
    start = np.abs(tiny.position - plain.position)[:, 0]
    assert start[:100].max() < 2e-5
    for name in ("position", "velocity", "current"):
        late = np.abs(getattr(tiny, name) - getattr(plain, name))[1500:, 0]
        assert late.max() < 1e-10 * np.abs(getattr(plain, name)).max(), name


def test_stiff_screw_with_a_damped_table_is_the_play_operator():
    # the table's damping dominating its inertia (time constant mass/damping = 0.4 ms) and a stiff screw: in the gap
    # the table stops at once, so it stands while the motor crosses the lost motion, as the play operator says
    h = 0.05
    servo = screw_axis(6600.0, damping=5e5)
    x, v, a = sine(8000, amplitude=1.0, hz=0.5)
    r = run([servo], DT, x, v, a, effects={"x": LoopEffects(backlash_mm=h)})
    motor = r.encoder[:, 0]
    table = r.position[:, 0]
    play = np.empty_like(motor)
    play[0] = table[0]
    for k in range(1, len(motor)):
        play[k] = min(max(play[k - 1], motor[k] - h / 2), motor[k] + h / 2)
    lost = np.ptp(motor) - np.ptp(table)  # the table's travel falls short of the motor's by the lost motion
    assert lost == pytest.approx(h, rel=0.05)
    assert np.abs(table - play).max() < 0.05 * h


def test_batch_equals_run_bit_for_bit_with_screw_backlash():
    servos = [screw_axis(150.0), screw_axis(6600.0, position_feedback="scale")]
    x, v, a = sine(1500)
    ref = np.hstack([x, 0.5 * x]), np.hstack([v, 0.5 * v]), np.hstack([a, 0.5 * a])
    variants = [(0.0, 0.0), (0.01, 0.0), (0.0, 0.004), (0.02, 0.01), (0.005, 0.0)]  # backlash of x and y [mm]
    rows, runs = [], []
    for hx, hy in variants:
        effects = {"x": LoopEffects(backlash_mm=hx, coulomb_N=30.0 * (hx > 0.005)), "y": LoopEffects(backlash_mm=hy)}
        rows.append([pack(s, DT, effects[name]) for name, s in zip("xy", servos)])
        runs.append(run(servos, DT, *ref, effects=effects))
    batch = run_batch(np.array(rows), DT, *ref, outputs=("tool", "encoder", "velocity", "current"))
    for b, r in enumerate(runs):
        for name, signal in (("tool", r.position), ("encoder", r.encoder), ("velocity", r.velocity),
                             ("current", r.current)):  # fmt: skip
            assert np.array_equal(batch[name][b], signal), (b, name)


def test_an_open_gap_leaves_the_table_at_rest_and_the_motor_side_alone_in_the_loop():
    # a gap wider than the motion: the table, at rest in its middle, is never touched, and the loop drives the motor
    # side alone, the rigid axis of mass m1 with its share of the damping (the kernel's rigid plant, packed apart)
    servo = screw_axis(150.0, kv=1000.0)
    x, v, a = sine(2000, amplitude=0.1)
    rows = np.array([[pack(servo, DT, LoopEffects(backlash_mm=1.0))],
                     [pack(AxisServo(mass=MOTOR, force_constant=KF, kv=1000.0, ti=TI, kp=KP, vff=VFF,
                                     damping=DAMPING * MOTOR / MASS), DT)]])  # fmt: skip
    out = run_batch(rows, DT, x, v, a, outputs=("tool", "encoder"))
    assert np.abs(out["encoder"][0] - x).max() > 1e-3  # the motor side moves
    assert np.array_equal(out["tool"][0], np.zeros_like(x))  # the table stays where it started
    # (with all the damping on the motor side: 1e-4 mm off)
    np.testing.assert_allclose(out["encoder"][0], out["encoder"][1], rtol=0, atol=1e-12)
