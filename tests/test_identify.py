"""Identification without a model (contoursim.identify): the drive structure and the gains, from positions only.

Two truths: contoursim's own kernel with a known drive structure, logged at
its servo period (so that the identified machine's period is the truth's and
its structures are the truth's candidates), and a trace of the independent
simulator of benchmarks/independent_truth.py, written apart from the kernel.
"""

import warnings
from dataclasses import replace

import numpy as np
import pytest

from contoursim import _parallel, paths
from contoursim.diagnosis import diagnose, synthetic_trace
from contoursim.feed import plan, sample
from contoursim.identify import WEAK_KP_VFF, delta_bic, identify_machine, identification_warnings, servo_period_for
from contoursim.machine import Machine
from contoursim.model import load_model
from contoursim.servo import AxisServo
from contoursim.traces import Trace
from contoursim.traces import read_trace

DT = 1e-3  # servo period [s], the traces logged at it


def own_trace(**drive):
    """A CCW circle on two PI axes of contoursim's kernel with the drive settings `drive`, 0.1 µm noise, fixed seed."""
    servo = dict(mass=100.0, force_constant=100.0, damping=0.0, kp=30.0, vff=0.0) | drive
    truth = Machine({"x": AxisServo(kv=150.0, ti=0.03, **servo), "y": AxisServo(kv=120.0, ti=0.04, **servo)}, DT)
    path = paths.iso230_4_circle(10.0, direction="ccw")
    reference = sample(path, plan(path, feed=2000 / 60, accel=1500.0, jerk=5e4), DT)
    return synthetic_trace(truth, reference, mismatch=0.0, noise_um=0.1, every=1, seed=5)


def structure(machine):
    """The identified drive structure of every axis, ``{(velocity_feedback, velocity_taps, computation_delay)}``."""
    return {(s.velocity_feedback, s.velocity_taps, s.computation_delay) for s in machine.axes.values()}


def test_a_drive_on_encoder_differences_with_a_computation_delay_is_identified_as_such():
    """The velocity from the encoder's backward difference, the command one period late: that structure, kp within 2 %."""
    identified = identify_machine(own_trace(velocity_feedback="difference", computation_delay=1))
    assert structure(identified) == {("difference", 1, 1)}
    assert identified.axes["x"].kp == pytest.approx(30.0, rel=0.02)


def test_a_drive_on_the_motor_velocity_is_not_given_a_difference():
    """The velocity loop on the motor velocity itself, no delay: the state structure, kp within 2 %."""
    identified = identify_machine(own_trace())
    assert structure(identified) == {("state", 1, 0)}
    assert identified.axes["x"].kp == pytest.approx(30.0, rel=0.02)


def test_an_axis_that_never_moves_leaves_the_others_loops_as_identified_wherever_it_stands():
    """A circle in YZ with X standing still: X's loop shows nowhere in the trace. Its parameters left free, they wandered
    (on this trace X's bandwidth ran to 5 rad/s), and on an outside tester's effect-free YZ circle the fit stuck there,
    leaving 24.9 µm RMS in 0.35 µm of noise (0.348 µm with the idle axis second). The idle axis now takes the loop of
    the first axis that moves, its own held out of the fit: the moving axes' loops come out as with the idle axis
    last, at the truth's bandwidths."""
    servo = dict(mass=100.0, force_constant=100.0, damping=0.0, kp=30.0, vff=0.0)
    loops = {"x": AxisServo(kv=140.0, ti=0.035, **servo), "y": AxisServo(kv=150.0, ti=0.03, **servo),
             "z": AxisServo(kv=120.0, ti=0.04, **servo)}
    path = paths.circle((5.0, 0.0, 0.0), 10.0, normal=(1.0, 0.0, 0.0))
    reference = sample(path, plan(path, feed=2000 / 60, accel=1500.0, jerk=5e4), DT)
    first = synthetic_trace(Machine(loops, DT), reference, mismatch=0.0, noise_um=0.1, every=1, seed=5)
    assert np.ptp(first.reference[:, 0]) == 0.0 and np.ptp(first.reference[:, 1:], axis=0).min() > 19.0
    last = Trace(first.t, first.reference[:, [1, 2, 0]], first.actual[:, [1, 2, 0]], ("x", "y", "z"))
    idle_first, idle_last = identify_machine(first), identify_machine(last)
    bandwidth = lambda servo: servo.kv * servo.force_constant / servo.mass  # noqa: E731  [rad/s]
    for moving, same in (("y", "x"), ("z", "y")):
        assert bandwidth(idle_first.axes[moving]) == pytest.approx(bandwidth(idle_last.axes[same]), rel=1e-3)
        assert bandwidth(idle_first.axes[moving]) == pytest.approx(bandwidth(loops[moving]), rel=0.1)
    assert idle_first.axes["x"] == idle_first.axes["y"]  # the first axis that moves lends its loop
    assert idle_first.axes["y"].kp == pytest.approx(30.0, rel=0.02)


def test_independent_drive_gains_are_identified(independent_truth, tmp_path):
    """An independent rigid axis pair (PI on encoder differences, current loop, 0.25 ms servo logged at 1 ms) with
    velocity feedforward 0.8: the steady lag (1 − vff)/kp within 2 %, vff within 0.03 of the data sheet's and the
    shared kp, which sets only a fifth of that lag, within 10 % (8 % low with the damping identified: 6/s against
    the truth's 3/s, taking the lags of the current loop and the screw the identified loop lacks), no weak-kp
    warning."""
    case = independent_truth.make_case("rigid", None, 22, tmp_path)
    sheet = load_model(case.machine_file).machine.axes["x"]
    assert sheet.vff == 0.8
    machine = identify_machine(read_trace(case.csv))
    identified = machine.axes["x"]
    assert (1 - identified.vff) / identified.kp == pytest.approx((1 - sheet.vff) / sheet.kp, rel=0.02)
    assert identified.kp == pytest.approx(sheet.kp, rel=0.1)
    assert identified.vff == pytest.approx(0.8, abs=0.03)
    assert not any("weakly determined" in w for w in identification_warnings(machine))


def test_a_sampled_drive_with_viscous_damping_is_identified_where_the_state_structure_shows_neither(
        independent_truth, tmp_path):
    """An effect-free independent rigid pair on a circle (PI on encoder differences, x's filtered, a computation delay
    and a current loop at a 0.25 ms servo logged at 1 ms; viscous damping 1.5/s and 2.0/s): on the state structure
    the damping was not significant, and the drive structures were fitted without it: the state structure was kept,
    1.39 and 0.91 µm RMS left in 0.14 µm of noise, enough to hide a cyclic error of 1.2 µm. Fitted with the damping
    free too, the backward difference is chosen, the loops are the truth's (its kp, each axis's velocity-loop
    bandwidth kv·Kf/m and integral time within 10 %) and what is left is about the noise."""
    case = independent_truth.make_case("rigid", None, 1014583970, tmp_path)
    trace = read_trace(case.csv)
    machine = identify_machine(trace)
    assert structure(machine) == {("difference", 1, 0)}
    sheet = load_model(case.machine_file, check=False).machine
    for a, s in sheet.axes.items():
        identified = machine.axes[a]
        assert identified.kp == pytest.approx(s.kp, rel=0.1)
        bandwidth = identified.kv * identified.force_constant / identified.mass
        assert bandwidth == pytest.approx(s.kv * s.force_constant / s.mass, rel=0.1)
        assert identified.ti == pytest.approx(s.ti, rel=0.1)
    result = diagnose(trace)
    assert result.effects == (), result.report()
    assert result.steps[-1].rms_um < 1.25 * np.linalg.norm(result.noise_um)  # 0.232 in 0.200 µm


def test_a_feedforward_beyond_the_reach_of_a_fit_started_without_one_is_found(independent_truth, tmp_path):
    """An independent two-mass pair with velocity feedforward 0.8 whose steady lag a position gain of 172 1/s without
    feedforward imitates well enough that a fit started there stays (the (kp, vff) valley's other end): searched from
    both ends, kp within 10 % and vff within 0.03 of the data sheet's."""
    case = independent_truth.make_case("two_mass", None, 1048233697, tmp_path)
    sheet = load_model(case.machine_file).machine.axes["x"]
    assert sheet.vff == 0.8
    identified = identify_machine(read_trace(case.csv)).axes["x"]
    assert identified.kp == pytest.approx(sheet.kp, rel=0.1)
    assert identified.vff == pytest.approx(0.8, abs=0.03)


def test_loops_far_from_the_regressions_start_are_found(independent_truth, tmp_path):
    """An independent two-mass trefoil whose velocity loops are only 1.5 times as fast as their position loop, behind a
    feedforward of 0.8 and a PI loop with damping: every stage of the fit started from the regression's P loop stayed
    in its valley (no feedforward, kp 222 1/s, bandwidths of 27 and 53 rad/s), leaving 84.6 µm RMS in 0.3 µm of
    noise. The fit from the best point of a coarse grid finds the data sheet's feedforward within 0.03 and each axis's
    velocity-loop bandwidth kv·Kf/m within 10 %."""
    case = independent_truth.make_case("two_mass", "thermal_drift", 322301094, tmp_path)
    sheet = load_model(case.machine_file, check=False).machine
    identified = identify_machine(read_trace(case.csv))
    assert identified.axes["x"].vff == pytest.approx(sheet.axes["x"].vff, abs=0.03)
    for a, s in sheet.axes.items():
        bandwidth = identified.axes[a].kv * identified.axes[a].force_constant / identified.axes[a].mass
        assert bandwidth == pytest.approx(s.kv * s.force_constant / s.mass, rel=0.1)


def test_an_offset_of_the_measured_positions_changes_nothing_identified():
    """The trace's zero is not the loop's: the same trace with each axis's measured positions offset (an instrument's
    zero, a squareness at the path's place) identifies the same machine, whatever the offsets."""
    trace = own_trace(vff=0.6)
    offset = replace(trace, actual=trace.actual + np.array([0.05, -0.12]))
    moved, identified = identify_machine(offset), identify_machine(trace)
    assert structure(moved) == structure(identified)
    for axis, servo in identified.axes.items():
        for name in ("kp", "vff", "kv", "ti", "damping"):
            assert getattr(moved.axes[axis], name) == pytest.approx(getattr(servo, name), rel=1e-6), (axis, name)


def test_a_squareness_at_the_machine_s_place_does_not_bend_the_identified_loops(independent_truth, tmp_path):
    """An independent rigid pair on a circle centred 261 mm up Y, X out of square by 191 µrad: X's measured positions
    sit 50 µm off its commands all along. Fitted with that offset in the residual, the loops bent to it (kp 159 1/s
    and no feedforward, the data sheet's 30.9 and 0.8: the offset correlated the residual over the whole run and the
    feedforward's mark counted for nothing); without it, the data sheet's steady lag within 2 % and vff within 0.05."""
    case = independent_truth.make_case("rigid", "squareness", 444329031, tmp_path)
    sheet = load_model(case.machine_file).machine.axes["x"]
    identified = identify_machine(read_trace(case.csv)).axes["x"]
    assert (1 - identified.vff) / identified.kp == pytest.approx((1 - sheet.vff) / sheet.kp, rel=0.02)
    assert identified.vff == pytest.approx(sheet.vff, abs=0.05)


def test_full_feedforward_leaves_kp_weakly_determined_and_the_diagnosis_says_so(independent_truth, tmp_path):
    """Velocity feedforward 1 (independent truth): the identified vff reaches WEAK_KP_VFF and the diagnosis without a
    model warns that kp is weakly determined, beside the drive structure it identified."""
    case = independent_truth.make_case("rigid", None, 32, tmp_path)
    assert load_model(case.machine_file).machine.axes["x"].vff == 1.0
    result = diagnose(read_trace(case.csv))
    assert result.model.machine.axes["x"].vff >= WEAK_KP_VFF
    said = identification_warnings(result.model.machine)
    assert any(w.startswith("identified drive structure: ") for w in said)
    assert any("kp" in w and "weakly determined" in w for w in said)
    assert all(w in result.warnings for w in said), result.warnings


def test_the_weak_kp_warning_is_judged_on_the_refitted_feedforward_too():
    """An identified vff of 0.88 under WEAK_KP_VFF that the diagnosis's refit takes to 0.906: the report gives 0.906,
    so kp is said to be weakly determined, with both values; a refit that stays under the threshold says nothing."""
    servo = AxisServo(mass=100.0, force_constant=100.0, damping=0.0, kp=30.0, kv=150.0, ti=0.03, vff=0.88)
    identified = Machine({"x": servo, "y": servo}, DT)
    refit = Machine({"x": replace(servo, vff=0.906), "y": replace(servo, vff=0.87)}, DT)
    assert not any("weakly determined" in w for w in identification_warnings(identified))
    said = [w for w in identification_warnings(identified, refit) if "weakly determined" in w]
    assert len(said) == 1 and "0.88 (0.906 as refitted)" in said[0]
    stays = Machine({"x": replace(servo, vff=0.89), "y": servo}, DT)
    assert not any("weakly determined" in w for w in identification_warnings(identified, stays))


def test_viscous_damping_behind_a_pi_loop_is_identified_as_its_mechanical_pole():
    """A PI axis pair with damping c/m = 5/s (the kernel's own truth, mass as assumed): the identified damping within
    20 %; the same pair undamped keeps the fit without it (ΔBIC not significant)."""
    identified = identify_machine(own_trace(velocity_feedback="difference", computation_delay=1, damping=500.0))
    for servo in identified.axes.values():
        assert servo.damping == pytest.approx(500.0, rel=0.2)
    assert all(s.damping == 0.0 for s in identify_machine(own_trace()).axes.values())


def test_an_independent_null_trace_without_a_model_names_nothing(independent_truth, tmp_path):
    """An independent rigid pair with nothing hidden (viscous damping in its guideways, a PI loop on encoder
    differences, a current loop): without the damping the identified loop left 1.64 µm of structure, which a
    Coulomb friction fitted as an effect; with it the residual falls near the noise and nothing is named. The
    corrected model carries the identified damping."""
    case = independent_truth.make_case("rigid", None, 508082495, tmp_path)
    result = diagnose(read_trace(case.csv))
    assert result.effects == ()
    assert result.steps[-1].rms_um < 2.0 * np.linalg.norm(result.noise_um)
    (tmp_path / "corrected.toml").write_text(result.corrected_model(), encoding="utf-8")
    corrected = load_model(tmp_path / "corrected.toml").machine.axes
    assert any(s.damping > 0 for s in corrected.values())
    assert all(corrected[a].damping == pytest.approx(s.damping) for a, s in result.refitted.machine.axes.items())


def test_loops_identified_around_an_independent_backlash_follow_it_on_two_masses_at_a_fine_servo_period(
        independent_truth, tmp_path):
    """An independent rigid axis pair whose Y has a 15.7 µm play in its screw, read by the motor's encoder (the table
    coasts across the play until the screw's force on it turns; the drive at 0.25 ms, logged at 1 ms), on a square.
    Held on a rigid axis, a play stops the table as the motor turns back, and loops sampled at 1 ms do not follow the
    motor across it: identified with a 15 µm play held that way, the loops left 9.72 µm RMS at 1 ms and 9.71 at 0.25
    ms (9.32 on two masses at 1 ms), more than the 6.30 of the loops identified without it. Held as identify_machine
    holds it now (two masses, read where the backlash is, at 0.25 ms), they leave a fifteenth of that (0.41 µm)."""
    from contoursim.effects import Effect
    from contoursim.model import Model
    from contoursim.simulation import measured_reference, simulate_batch

    case = independent_truth.make_case("rigid", "backlash", 745104971, tmp_path)
    assert case.path == "square"
    assert [(t["axis"], t["options"]["feedback"]) for t in case.truths] == [("y", "motor")]
    trace = read_trace(case.csv)

    def left(machine, effects):
        reference = measured_reference(trace, machine.servo_period)
        y = simulate_batch([Model(machine, effects)], reference, settle=0.0, check=False)["tool_position"][0]
        r = trace.actual - np.column_stack([np.interp(trace.t, reference.t, y[:, i]) for i in range(y.shape[1])])
        return 1e3 * np.sqrt(np.sum(np.mean((r - r.mean(axis=0)) ** 2, axis=0)))  # RMS of the error vector [µm]

    play = Effect("backlash", "y", lost_motion_um=15.0, feedback="motor")
    machine = identify_machine(trace, effects=(play,))
    y = machine.axes["y"]
    assert (y.compliant, y.position_feedback, machine.servo_period) == (True, "motor", pytest.approx(2.5e-4))
    assert not machine.axes["x"].compliant
    assert any("axis y identified as two masses" in w for w in identification_warnings(machine))
    unheld = identify_machine(trace)
    without = left(unheld, ())
    assert left(machine, (play,)) < without / 5, without
    # one fit from the loops identified without it, as a diagnosis's held search ranks the effects it holds
    started = identify_machine(trace, effects=(play,), start=unheld)
    assert started.axes["y"].compliant and started.servo_period == pytest.approx(2.5e-4)
    assert left(started, (play,)) < without / 5, without


def test_loops_fitted_from_a_start_away_from_them_are_the_truth():
    """The kernel's own PI pair on encoder differences, the command a period late, damped (c/m = 5/s): fitted from
    loops on that structure with kp 15 % high, each bandwidth 20 % low, each ti 50 % long and a fifth of the damping,
    the truth's kp within 2 %, kv within 5 %, damping within 20 %."""
    truth = dict(velocity_feedback="difference", computation_delay=1, damping=500.0)
    trace = own_trace(**truth)
    servo = dict(mass=100.0, force_constant=100.0, kp=34.5, vff=0.0, damping=100.0, velocity_feedback="difference",
                 computation_delay=1)
    start = Machine({"x": AxisServo(kv=120.0, ti=0.045, **servo), "y": AxisServo(kv=96.0, ti=0.06, **servo)}, DT)
    fitted = identify_machine(trace, start=start)
    assert structure(fitted) == {("difference", 1, 1)}
    assert fitted.axes["x"].kp == pytest.approx(30.0, rel=0.02)
    assert [fitted.axes[a].kv for a in "xy"] == pytest.approx([150.0, 120.0], rel=0.05)
    assert [fitted.axes[a].damping for a in "xy"] == pytest.approx([500.0, 500.0], rel=0.2)


@pytest.mark.parametrize("start", [False, True], ids=["staged search", "from a start"])
def test_fits_run_side_by_side_on_the_cores_identify_what_they_identify_one_after_the_other(monkeypatch, start):
    """The fits that do not depend on each other (the valley's two ends, each drive structure) run in forked processes
    where the machine has the cores (contoursim._parallel.fork_map): the machine identified is the same, to the last
    bit, as with every fit in this process one after the other."""
    trace = own_trace(velocity_feedback="difference", computation_delay=1, damping=500.0)
    servo = dict(mass=100.0, force_constant=100.0, kp=34.5, vff=0.0, damping=100.0)
    begin = Machine({"x": AxisServo(kv=120.0, ti=0.045, **servo), "y": AxisServo(kv=96.0, ti=0.06, **servo)}, DT)
    side_by_side = identify_machine(trace, start=begin if start else None)
    monkeypatch.setattr(_parallel, "_cores", lambda: 1)
    assert identify_machine(trace, start=begin if start else None) == side_by_side


def test_a_trace_too_short_or_a_period_that_is_no_number_is_refused_by_name():
    """Five samples gave loops of kp 311 1/s (diagnose refused them, identify_machine did not); servo_period "abc" was
    float()'s "could not convert string to float"."""
    trace = own_trace()
    short = Trace(trace.t[:5], trace.reference[:5], trace.actual[:5], trace.axes)
    with pytest.raises(ValueError, match="identifying the servo loops needs at least 16 samples, the trace has 5"):
        identify_machine(short)
    with pytest.raises(TypeError, match="servo_period"):
        identify_machine(trace, servo_period="abc")
    with pytest.raises(TypeError, match="trace must be a Trace"):
        identify_machine(trace.actual)


ONE_AXIS = Machine({"x": AxisServo(mass=100.0, force_constant=100.0, kv=100.0)}, DT)


@pytest.mark.parametrize("start, named", [("fast", "str"), (ONE_AXIS, "one with x")])
def test_a_start_that_is_not_a_machine_with_the_traces_axes_is_refused_by_name(start, named):
    with pytest.raises(TypeError, match=f"start must be a Machine with the trace's axes x, y, got {named}"):
        identify_machine(own_trace(), start=start)


@pytest.mark.parametrize("start", [0.0, 86400.0, 1e7])
def test_a_trace_logged_every_ms_is_simulated_at_1_ms_whatever_its_clock_reads(start):
    """A logger whose clock started a day earlier: a step of its times read 1.0000000038 ms, and the identified
    loops ran at 0.5 ms, naming other effects than the same trace with its clock at 0."""
    t = np.round(start + np.arange(3000) * 1e-3, 6)  # as a CSV with µs writes them
    x = np.sin(t - start)[:, None]
    assert servo_period_for(Trace(t, x, x, ("x",)).dt) == pytest.approx(1e-3, rel=1e-9)


def test_delta_bic_is_its_closed_form_and_minus_infinity_for_a_model_that_diverged_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the ratio 1e-300 / inf underflowed to 0, and numpy warned of log(0)
        assert delta_bic(1.0, np.inf, 100, 1, 1.0) == -np.inf
        assert delta_bic(0.0, 0.0, 100, 1, 1.0) == pytest.approx(-np.log(100))  # followed exactly either way
        assert delta_bic(2.0, 1.0, 400, 3, 4.0) == pytest.approx(100 * np.log(2.0) - 3 * np.log(100))
