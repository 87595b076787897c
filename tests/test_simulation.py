"""The whole pipeline (path -> servo kernel -> tool -> contour error) against independent references."""

import warnings

import control as ct
import numpy as np
import pytest

from contoursim import _memory, paths
from contoursim.exceptions import ContoursimWarning
from contoursim.feed import plan, sample
from contoursim.traces import Trace, read_trace
from contoursim.machine import Machine
from contoursim.plotting import circular_deviation
from contoursim.servo import AxisServo
from contoursim.trajectory import Trajectory
from contoursim.simulation import default_settle, measured_force, measured_reference, simulate, simulate_batch

DT = 2e-4
AXIS = dict(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, damping=500.0)


def _circle_run(kp_x, kp_y, radius=20.0, feed=40.0):
    machine = Machine({"x": AxisServo(kp=kp_x, **AXIS), "y": AxisServo(kp=kp_y, **AXIS)}, DT)
    path = paths.circle(center=(0, 0), radius=radius, direction="ccw", start_angle=0.0, role="test")
    path = paths.join(*(path,) * 3)  # three turns: the last one is in steady state
    trajectory = sample(path, plan(path, feed=feed, accel=2000.0), DT)
    return machine, simulate(machine, trajectory, settle=0.0), radius, feed


def _last_turn(result, radius, feed):
    """Samples of the last turn at full feed: the loops are in steady state there."""
    traj = result.trajectory
    return (traj.s > traj.s[-1] - 2 * np.pi * radius * 0.95) & (traj.speed > 0.999 * feed)


@pytest.mark.parametrize("kp_x, kp_y", [(40.0, 40.0), (40.0, 30.0)])
def test_steady_state_circle_matches_python_control_frequency_response(kp_x, kp_y):
    """Each axis settles to R·|T(jω)| at phase ∠T(jω) (python-control); the radial error follows.

    With equal gains the circle just shrinks; with unequal gains it becomes the
    45° ellipse of a gain mismatch. Either way the simulated radial deviation
    over the last turn equals the one predicted from the two axes' closed-loop
    frequency responses.
    """
    machine, result, radius, feed = _circle_run(kp_x, kp_y)
    omega = feed / radius
    tx, ty = (complex(ct.frequency_response(machine.axes[a].closed_loop(), [omega]).complex.squeeze()) for a in "xy")
    last = _last_turn(result, radius, feed)
    angle = result.trajectory.s[last] / radius
    predicted = np.column_stack([radius * abs(tx) * np.cos(angle + np.angle(tx)),
                                 radius * abs(ty) * np.sin(angle + np.angle(ty))])
    dev_sim = np.linalg.norm(result.tool_position[last], axis=1) - radius
    dev_pred = np.linalg.norm(predicted, axis=1) - radius
    np.testing.assert_allclose(dev_sim, dev_pred, atol=1e-3 * np.abs(dev_pred).max() + 1e-7)
    # on a circle the exact contour error is the radial deviation
    np.testing.assert_allclose(result.contour.normal[last], -dev_sim, atol=1e-9)


def test_gain_mismatch_gives_a_45_degree_ellipse():
    """Unequal Kp: the phase difference between the axes makes a 45° ellipse.

    The radial deviation is c + a·sin 2θ + b·cos 2θ. The phase difference
    (∝ ω/Kp) gives the sin 2θ term, the magnitude difference (∝ (ω/Kp)²) the
    cos 2θ term, so the ellipse's axis leaves 45° by about ω/Kp at most.
    """
    kp_x, kp_y = 40.0, 30.0
    _, result, radius, feed = _circle_run(kp_x, kp_y)
    p = result.tool_position[_last_turn(result, radius, feed)]
    theta = np.arctan2(p[:, 1], p[:, 0])
    dev = np.hypot(p[:, 0], p[:, 1]) - radius
    basis = np.column_stack([np.ones_like(theta), np.sin(2 * theta), np.cos(2 * theta)])
    (_, a, b), *_ = np.linalg.lstsq(basis, dev, rcond=None)
    omega = feed / radius
    assert abs(a) > 0.5 * radius * omega * (1 / kp_y - 1 / kp_x) / 2  # the 45° term is there
    assert abs(np.arctan(b / a) / 2) < omega / min(kp_x, kp_y)


def test_tracking_error_is_v_over_kp_while_contour_error_is_small():
    """Tracking error ≈ v/Kp; contour error ≈ R(1 − |T(jω)|) of a first-order lag, 40× smaller here."""
    kp = 40.0
    _, result, radius, feed = _circle_run(kp, kp)
    steady = _last_turn(result, radius, feed)
    tracking = np.linalg.norm(result.tracking_error[steady], axis=1)
    assert np.median(tracking) == pytest.approx(feed / kp, rel=0.02)
    first_order_lag = radius * (1 - 1 / np.hypot(1, feed / radius / kp))
    assert result.contour.magnitude[steady].mean() == pytest.approx(first_order_lag, rel=0.05)


def test_sampling_must_match_the_servo_period():
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.circle(center=(0, 0), radius=5.0)
    with pytest.raises(ValueError, match="servo period"):
        simulate(machine, sample(path, plan(path, feed=10.0, accel=500.0), 2 * DT))


def test_a_3d_path_needs_three_axes():
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.helix(center=(0, 0, 0), radius=5.0, pitch=2.0, turns=1)
    with pytest.raises(ValueError, match="3 coordinates but the machine has only 2 axes"):
        simulate(machine, sample(path, plan(path, feed=10.0, accel=500.0), DT))


def test_saved_trace_follows_the_csv_contract(tmp_path):
    _, result, _, _ = _circle_run(40.0, 40.0, radius=2.0, feed=5.0)
    result.save_csv(tmp_path / "run.csv", metadata={"path": "circle"})
    trace = read_trace(tmp_path / "run.csv")
    assert trace.axes == ("x", "y")
    assert trace.metadata["path"] == "circle" and trace.metadata["servo_period_s"] == f"{DT:g}"
    assert float(trace.metadata["feed_mm_min"]) == pytest.approx(60 * 5.0)
    np.testing.assert_allclose(trace.reference, result.trajectory.position, rtol=0, atol=0.5e-6 + 1e-12)
    np.testing.assert_allclose(trace.actual, result.tool_position, rtol=0, atol=0.5e-6 + 1e-12)
    with pytest.raises(FileExistsError):
        result.save_csv(tmp_path / "run.csv")
    # the metadata given cannot declare other units than the file's (t [ms] read the times back 1000 times too short)
    with pytest.raises(ValueError, match="metadata 'units': declares column 't' in 'ms'"):
        result.save_csv(tmp_path / "ms.csv", metadata={"units": "t [ms]"})
    with pytest.raises(ValueError, match="'units' and 'Units' are both a '# units:' line"):
        result.save_csv(tmp_path / "ms.csv", metadata={"Units": "m"})
    for call in (lambda: result.save_csv(tmp_path / "ms.csv", metadata=[("path", "circle")]),
                 lambda: result.to_trace("circle")):
        with pytest.raises(TypeError, match="metadata must map keys to values"):
            call()
    assert not (tmp_path / "ms.csv").exists()


SQUARE_XY = """
tool = "tool"
workpiece = "workpiece"

[[body]]
name = "Y"
parent = "bed"
joint = "linear -y"
axis = "y"

[[body]]
name = "X"
parent = "Y"
joint = "linear -x"
axis = "x"
squareness = {{ y_urad = {alpha_urad} }}

[[body]]
name = "workpiece"
parent = "X"

[[body]]
name = "tool"
parent = "bed"
"""


def test_squareness_enters_the_trace_and_geometric_compensation_removes_it():
    """Squareness α of X on Y: a 45° ellipse of radial deviation ∓(αR/2)·sin 2θ in the static error.

    The servo half is identical with and without the error, so the geometric
    part of the tool-tip error is the difference of the two runs; compensated,
    the machine contours like the error-free one.
    """
    from contoursim.config import TomlFile
    from contoursim.geocomp import GeometricCompensation
    from contoursim.multibody import chain_from_toml

    alpha = 200e-6
    chain = chain_from_toml(TomlFile("square.toml", SQUARE_XY.format(alpha_urad=alpha * 1e6)))
    servos = {"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}
    radius, feed = 50.0, 1000 / 60
    path = paths.iso230_4_circle(radius)
    trajectory = sample(path, plan(path, feed=feed, accel=1000.0), DT)
    skewed = simulate(Machine(servos, DT, chain), trajectory)
    plain = simulate(Machine(servos, DT), trajectory)
    fixed = simulate(Machine(servos, DT, chain), trajectory, [GeometricCompensation(chain)])

    test = skewed.trajectory.measuring
    p = skewed.static_tool_position[test]
    theta = np.arctan2(p[:, 1], p[:, 0])
    radial = np.hypot(p[:, 0], p[:, 1]) - radius
    first_order = -alpha * radius / 2 * np.sin(2 * theta)  # sign: S > 0 opens the XY angle beyond 90°
    np.testing.assert_allclose(radial, first_order, atol=alpha**2 * radius)
    # geometric and servo errors add in the actual trace, up to the cross term α·(tracking error)
    geometric = skewed.tool_position - plain.tool_position
    cross = alpha * np.abs(plain.tracking_error).max()
    np.testing.assert_allclose(geometric, skewed.volumetric_error, rtol=0, atol=1.01 * cross)
    assert cross < 0.02 * np.abs(skewed.volumetric_error).max()
    # compensation: no static error left, and the contour error is the servo's alone
    assert np.abs(fixed.volumetric_error).max() < 1e-9
    np.testing.assert_allclose(fixed.contour.magnitude, plain.contour.magnitude, atol=1e-9)
    # squareness moves y by α·x: the largest static error on the test circle is α·R
    assert skewed.summary()["volumetric_max_um"] == pytest.approx(1e3 * alpha * radius, rel=1e-3)
    # a ballbar sees the ellipse: circularity (max - min radial deviation) α·R; equal servo axes only
    # shrink the circle uniformly, so without the error (or compensated) the circle stays round
    assert circular_deviation(skewed)["circularity"] == pytest.approx(1e3 * alpha * radius, rel=0.01)
    assert circular_deviation(plain)["circularity"] < 0.01 * 1e3 * alpha * radius
    assert circular_deviation(fixed)["circularity"] < 0.01 * 1e3 * alpha * radius
    assert plain.summary()["volumetric_max_um"] == 0.0


def test_paths_are_placed_at_the_work_offset_and_kept_inside_the_travel():
    """The path's origin sits where the tool is at the home axis positions; travel and axis span are checked."""
    from contoursim.machine import load_machine

    mill = load_machine("vertical_mill_3axis")
    path = paths.circle(center=(0, 0), radius=20.0)
    trajectory = sample(path, plan(path, feed=20.0, accel=1000.0), mill.servo_period)
    q, _, _ = mill.axis_commands(trajectory)
    # the table axes move opposite to the tool ("linear -x"): the circle is drawn about mid-travel
    np.testing.assert_allclose(q.min(axis=0), [230.0, 180.0, -150.0], atol=1e-9)
    np.testing.assert_allclose(q.max(axis=0), [270.0, 220.0, -150.0], atol=1e-9)
    # the ideal machine returns the path itself in the path's coordinates
    ideal = Machine(dict(mill.axes), mill.servo_period, mill.chain.ideal())
    np.testing.assert_allclose(ideal.tool_position(q, trajectory.t, 2), trajectory.position, atol=1e-9)
    # moved to the edge of the table, the circle would leave the X travel
    shifted = Machine(dict(mill.axes), mill.servo_period, mill.chain, work_offset={"x": 490.0})
    with pytest.raises(ValueError, match=r"axis x would move over 470 .. 510, outside its travel 0 .. 500"):
        shifted.axis_commands(trajectory)
    # an XZ machine cannot follow an XY circle
    lathe = load_machine("diamond_lathe")
    with pytest.raises(ValueError, match=r"linear axes \(x, z\) cannot move the tool along the path"):
        lathe.axis_commands(sample(path, plan(path, feed=20.0, accel=1000.0), lathe.servo_period))


def test_saturation_is_reported_by_axis_and_fraction():
    """A current limit below what the path's acceleration needs must clip; a generous one must not.

    The ramp up to feed needs a force m·a = 300 kg · 2 m/s² = 600 N, i.e. 0.64 A at
    942 N/A (plus the damping's 0.5 N·s/mm · v). At 0.2 A the x axis cannot follow;
    at 20 A (30× the need) nothing clips.
    """
    path = paths.line((0, 0), (20, 0))
    trajectory = sample(path, plan(path, feed=40.0, accel=2000.0), DT)
    axes = lambda limit: {"x": AxisServo(current_limit=limit, **AXIS), "y": AxisServo(**AXIS)}  # noqa: E731
    with pytest.warns(ContoursimWarning) as record:
        starved = simulate(Machine(axes(0.2), DT), trajectory)
    fraction = starved.saturation["x"]
    assert starved.saturation["y"] == 0.0 and 0 < fraction < 1
    clipped = np.abs(starved.servo_response.current[:, 0]) >= 0.2 * (1 - 1e-12)
    assert fraction == pytest.approx(clipped.mean())
    assert [str(w.message) for w in record] == [
        f"the current command hit its limit on axis x in {100 * fraction:.3g} % of the samples (limit ±0.2 A): "
        "the errors include the saturation"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ample = simulate(Machine(axes(20.0), DT), trajectory)
    assert ample.saturation == {"x": 0.0, "y": 0.0}
    # unclipped, the lag is v/Kp = 1 mm; clipped, the axis falls further behind
    assert ample.summary()["tracking_max_um"] == pytest.approx(1e3 * 40.0 / 40.0, rel=0.02)
    assert starved.summary()["tracking_max_um"] > 1.1 * ample.summary()["tracking_max_um"]


def test_an_axis_its_drive_cannot_push_is_said_never_to_have_moved():
    """A friction of 20 kN on X, whose drive pushes at most 942 N/A · 20 A = 18.84 kN: X stands still all along, a
    run that read as an ordinary one (its contour error the path's size); the saturation warning says so. At 18 kN
    X breaks away, clipped for a while, and the warning is the plain one."""
    from contoursim.effects import Effect
    from contoursim.model import Model

    path = paths.line((0, 0), (20, 0))
    trajectory = sample(path, plan(path, feed=40.0, accel=2000.0), DT)
    machine = Machine({"x": AxisServo(kp=40.0, current_limit=20.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    for force, says in ((2e4, True), (1.8e4, False)):
        with pytest.warns(ContoursimWarning) as record:
            result = simulate(Model(machine, (Effect("coulomb_friction", "x", force_N=force),)), trajectory)
        assert (np.ptp(result.servo_response.position[:, 0]) < 1e-9) == says
        message = str(record[0].message)
        assert message.startswith("the current command hit its limit on axis x in ")
        assert ("(limit ±20 A; it never moved, commanded over 20 mm: the most its drive pushes, 1.884e+04 N, does not "
                "overcome what holds it): the errors include the saturation" in message) == says


def test_the_api_refuses_a_path_faster_than_the_machine_allows_like_the_cli():
    machine = Machine({"x": AxisServo(**AXIS), "y": AxisServo(**AXIS)}, DT, max_feed=5000 / 60)  # [mm/s]
    path = paths.line((0, 0), (50, 0))
    fast = sample(path, plan(path, feed=6000 / 60, accel=2000.0), DT)
    with pytest.raises(ValueError, match=r"the trajectory reaches 6000 mm/min \(100 mm/s\) at t = .* s, above the "
                                         r"machine's max feed 5000 mm/min"):
        simulate(machine, fast)
    with pytest.raises(ValueError, match=r"feed 100 mm/s \(6000 mm/min, segment 0\) exceeds max_feed"):
        plan(path, feed=6000 / 60, accel=2000.0, max_feed=machine.max_feed)
    at_limit = sample(path, plan(path, feed=5000 / 60, accel=2000.0), DT)
    assert simulate(machine, at_limit).trajectory.speed.max() == pytest.approx(5000 / 60)


def test_what_follows_a_run_allocates_no_arrays_of_its_length(tmp_path):
    """The contour error, the summary, the trace CSV and the plots of a run, measured with tracemalloc at two lengths.

    Per extra step, the peak of what each allocates may hold the contour error's results
    (magnitude, s, normal, 2-D foot: 40 bytes) and its two int32 search indices, a summary's one
    error at a time (8 bytes), a few bytes for the CSV's and the plots' checks and picks: no
    (N, d) temporary (16 bytes a step in 2-D) beside a finished run.
    """
    import tracemalloc

    from contoursim.contour import exact_contour_error
    from contoursim.plotting import save_figures

    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=36.0, **AXIS)}, DT)
    path = paths.circle(center=(0, 0), radius=20.0)
    peaks = {}
    for feed in (6.0, 2.0):  # ~105 k and ~314 k steps
        result = simulate(machine, sample(path, plan(path, feed=feed, accel=2000.0), DT), settle=0.0)
        out = tmp_path / f"feed_{feed:g}"
        jobs = dict(
            contour=lambda: exact_contour_error(result.trajectory, result.tool_position),
            summary=result.summary,
            csv=lambda: result.save_csv(tmp_path / f"feed_{feed:g}.csv", overwrite=True),
            plots=lambda: save_figures({"run": result}, out, "run"),
        )
        for name, job in jobs.items():
            job()  # compiled, imported, cached: what a second call allocates is the job's own
            tracemalloc.start()
            try:
                base = tracemalloc.get_traced_memory()[0]
                job()
                peaks.setdefault(name, []).append((len(result.trajectory), tracemalloc.get_traced_memory()[1] - base))
            finally:
                tracemalloc.stop()
    limits = dict(contour=52, summary=16, csv=4, plots=8)  # [bytes per step]
    for name, ((n1, p1), (n2, p2)) in peaks.items():
        assert (p2 - p1) / (n2 - n1) <= limits[name], (name, (p2 - p1) / (n2 - n1))


# --- a measured trace's known force ----------------------------------------------------------


def _pushed_trace(force_at, level, logged_every=5):
    """A two-axis trace at standstill (x 2 mm, y -1 mm) logged every `logged_every` servo periods, with a force step
    of `level` [N] on y from the logged sample `force_at`."""
    t = np.arange(400) * logged_every * DT
    reference = np.column_stack([np.full(t.size, 2.0), np.full(t.size, -1.0)])
    force = np.where(np.arange(t.size) >= force_at, level, 0.0)
    return Trace(t, reference, reference, ("x", "y"), force={"y": force})


def test_a_traces_force_is_a_held_input_whose_standstill_error_is_the_closed_form():
    # P-P loops (no integrator): at rest the drive balances the force, kf·(kv/1000)·kp·(x_ref - x) + F = 0, so
    # y - y_ref = 1000·F/(kf·kv·kp) [mm]; x has no force and stays put. The force column is sampled every 5 servo
    # periods: held (zero-order) from its sample on, so nothing moves before the servo step at its time.
    servo = AxisServo(kp=40.0, mass=300.0, force_constant=942.0, kv=80.0, damping=500.0)
    machine = Machine({"x": servo, "y": servo}, DT)
    trace = _pushed_trace(force_at=100, level=-250.0)
    result = simulate(machine, trace, contour=False)
    y = result.tool_position[:, 1]
    step = 100 * 5  # the servo sample at the force's logged time
    assert np.array_equal(y[: step + 1], np.full(step + 1, -1.0))  # the force acts over [t_step, t_step+1) first
    assert y[step + 1] < -1.0
    assert y[-1] - (-1.0) == pytest.approx(1000.0 * -250.0 / (942.0 * 80.0 * 40.0), rel=1e-6)
    assert np.array_equal(result.tool_position[:, 0], np.full(len(y), 2.0))
    measured = measured_force(trace, DT)["y"]
    assert measured.size == len(y) and np.array_equal(np.flatnonzero(np.diff(measured)), [step - 1])


def test_a_batch_with_a_force_is_simulate_bit_for_bit_and_returns_the_current():
    servo = AxisServo(kp=40.0, **AXIS)
    machine = Machine({"x": servo, "y": servo}, DT)
    trace = _pushed_trace(force_at=50, level=400.0)
    models = [machine, Machine({"x": servo, "y": AxisServo(kp=30.0, **AXIS)}, DT)]
    batch = simulate_batch(models, trace, outputs=("tool_position", "current"))
    for b, model in enumerate(models):
        single = simulate(model, trace, contour=False)
        np.testing.assert_array_equal(batch["tool_position"][b], single.tool_position)
        np.testing.assert_array_equal(batch["current"][b], single.servo_response.current)
    assert batch["current"][0, -1, 1] == pytest.approx(-400.0 / 942.0, rel=1e-6)  # the PI loop's integrator holds it
    unforced = simulate_batch(models, Trace(trace.t, trace.reference, trace.actual, trace.axes), outputs=("current",))
    assert np.all(unforced["current"] == 0.0)


def test_a_simulated_force_is_written_with_the_result_and_read_back(tmp_path):
    # What a simulation was pushed by goes with its result: to_trace and save_csv carry the y_force column (as
    # held at the servo period), and simulating the file written gives the same positions again.
    servo = AxisServo(kp=40.0, **AXIS)
    machine = Machine({"x": servo, "y": servo}, DT)
    result = simulate(machine, _pushed_trace(force_at=50, level=-120.0), contour=False)
    assert set(result.force) == {"y"} and result.force["y"].shape == (len(result.tool_position),)
    np.testing.assert_array_equal(result.to_trace().force["y"], result.force["y"])
    result.save_csv(tmp_path / "pushed.csv")
    back = read_trace(tmp_path / "pushed.csv")
    assert set(back.force) == {"y"} and back.metadata["units"].count("y_force [N]") == 1
    np.testing.assert_allclose(back.force["y"], result.force["y"], rtol=0, atol=1e-6)
    again = simulate(machine, back, contour=False, settle=0.0)
    np.testing.assert_allclose(again.tool_position, back.actual, rtol=0, atol=2e-6)
    assert simulate(machine, _pushed_trace(force_at=50, level=0.0), contour=False).force.keys() == {"y"}


@pytest.mark.parametrize("limit", [0.15, 0.05])
def test_a_batchs_saturated_fraction_is_over_the_trace_not_its_run_in(limit):
    # A trace that starts moving is entered through a run-in, which may clamp too: the fraction is over the
    # trace's samples, as simulate's (it counted the run-in's clamped steps too, up to 131 % of the samples).
    servo = AxisServo(kp=40.0, current_limit=limit, **AXIS)
    machine = Machine({"x": servo, "y": servo}, DT)
    t = np.arange(400) * 1e-3
    reference = np.column_stack([50.0 * t, np.zeros_like(t)])
    trace = Trace(t, reference, reference, ("x", "y"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContoursimWarning)  # the clamping is the point
        single = simulate(machine, trace, contour=False)
        batch = simulate_batch([machine], trace, outputs=("summary",))
    assert 0.0 < batch["summary"]["saturated"][0] == max(single.saturation.values()) <= 1.0


def test_a_force_on_an_axis_the_machine_lacks_is_refused():
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    trace = _pushed_trace(force_at=10, level=5.0, logged_every=1)
    reference = measured_reference(trace, DT)
    with pytest.raises(ValueError, match=r"force names axis 'z', which is not a servo axis of the machine \(x, y\)"):
        simulate(machine, reference, force={"z": np.zeros(len(reference))})
    with pytest.raises(ValueError, match=r"force\['x'\] must have shape \(400,\)"):
        simulate_batch([machine], reference, force={"x": np.zeros(5)})


def test_a_measured_reference_that_ends_at_rest_is_held_by_the_default_settle_and_one_in_motion_is_refused():
    """The spline through a trace's commanded positions ends at rest to rounding (1e-41 mm/s, not 0): simulate holds
    it for its settle as it holds a planned reference; a reference that ends moving is refused, saying how fast."""
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS)}, DT)
    t = np.arange(1500) * DT
    position = (1 - np.cos(np.pi * np.clip(t / 0.28, 0.0, 1.0)))[:, None]  # at rest from 0.28 s
    reference = measured_reference(Trace(t, position, position, ("x",)), DT)
    assert 0 < np.abs(reference.velocity[-1]).max() < 1e-12
    assert len(simulate(machine, reference, contour=False).tool_position) > len(reference)
    moving = Trajectory(t, t[:, None], np.ones((t.size, 1)), np.zeros((t.size, 1)), t)
    with pytest.raises(ValueError, match=r"only a reference that ends at rest can be held; this one ends at 1 mm/s"):
        simulate(machine, moving, contour=False)


# --- a measured reference that starts in motion --------------------------------------------------


def _ramp(t, accel, t_move):
    """A command standing at 1 mm, then accelerating at `accel` [mm/s²] from `t_move` [s]: (position, velocity, acceleration)."""
    u = np.maximum(t - t_move, 0.0)
    return 1.0 + 0.5 * accel * u**2, accel * u, np.where(t >= t_move, accel, 0.0)


def test_a_trace_that_starts_accelerating_is_entered_as_the_machine_entered_it():
    # The command accelerates from rest at t = 0.05 s; a trace of it starts at 0.1 s, in motion. Its simulation steps
    # the run-in back to rest at the trace's first acceleration: the same commands as the whole motion's, so the
    # same positions from the trace's first sample on (to rounding), not a start at rest on a moving command.
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS)}, DT)
    t = np.arange(1500) * DT
    position, velocity, acceleration = (x[:, None] for x in _ramp(t, 400.0, 0.05))
    whole = simulate(machine, Trajectory(t, position, velocity, acceleration, position[:, 0] - 1.0), settle=0.0)
    cut = slice(500, None)
    trace = Trace(t[cut], position[cut], position[cut], ("x",))
    started = simulate(machine, trace, contour=False)
    np.testing.assert_allclose(started.tool_position, whole.tool_position[cut], rtol=0, atol=1e-9)
    assert np.abs(whole.tool_position[cut] - position[cut]).max() > 1e-3  # the axis lags by more than that: a start
    # at rest on the moving command would be off by as much at first


def test_a_trace_that_starts_at_constant_velocity_starts_in_the_steady_following_error():
    # P-P loop without damping: the steady ramp error is v/kp (test_kernel); after the run-in at the first velocity (no
    # acceleration) over default_settle (five position-loop time constants) the first sample is within 1 % of it.
    machine = Machine({"x": AxisServo(kp=40.0, mass=300.0, force_constant=942.0, kv=80.0)}, DT)
    t = np.arange(1000) * DT
    trace = Trace(t, (3.0 + 25.0 * t)[:, None], (3.0 + 25.0 * t)[:, None], ("x",))
    started = simulate(machine, trace, contour=False)
    assert trace.reference[0, 0] - started.tool_position[0, 0] == pytest.approx(25.0 / 40.0, rel=0.01)
    assert len(started.trajectory) == len(trace.t)


def test_a_loop_running_away_is_reported_diverged_not_as_figures_of_kilometres():
    # A variant's loop that grows without bound but is still finite when the run ends (the kernel checks for
    # non-finite states) was summarised as a contour error of 1e11 µm, or, a little faster, ended the batch in
    # 'magnitude contains a non-finite value (inf)' (a sweep varying ti; a diagnosis's candidate: overflow warnings).
    from dataclasses import replace

    from contoursim.effects import Effect
    from contoursim.exceptions import UnstableLoopError
    from contoursim.machine import load_machine
    from contoursim.model import Model

    machine = load_machine("demo_mill")
    line = paths.polyline([[0, 0], [2, 0]])
    trajectory = sample(line, plan(line, 10.0, 500.0, 50_000.0), machine.servo_period)
    variants = [replace(machine, axes={**machine.axes, "x": replace(machine.axes["x"], ti=machine.axes["x"].ti * f)})
                for f in (1.0, 0.003, 0.001)]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = simulate_batch(variants, trajectory, outputs=("summary", "tool_position"), check=False)
    np.testing.assert_array_equal(out["summary"]["diverged"], [False, True, True])
    assert np.isfinite(out["summary"]["contour_max_um"][0]) and np.isnan(out["summary"]["contour_max_um"][1:]).all()
    assert np.isnan(out["tool_position"][1:]).all() and (out["diverged_step"][1:, 0] > 0).all()
    assert (out["diverged_step"][:, 1:] == -1).all() and (out["diverged_step"][0] == -1).all()
    # the single run: a feedback delay of 50 periods makes x's loop grow, still finite where the run ends
    with pytest.raises(UnstableLoopError, match=r"the simulation of axis 'x' ran away beyond ±1e\+06 mm by t = "):
        simulate(Model(machine, (Effect("time_delay", "x", delay_s=0.01, kind="feedback"),)), trajectory)


def test_a_batch_keeping_the_first_sample_alone_is_refused_naming_every():
    # simulate_batch(..., every=10**6) returned the run's first sample alone (t of shape (1,)) without a word
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.line((0, 0), (0.2, 0))
    trajectory = sample(path, plan(path, feed=10.0, accel=500.0), DT)
    n = len(trajectory)
    for every in (n, 10**6):
        with pytest.raises(ValueError, match=rf"every = {every} keeps only the first of the run's {n} samples: give "
                                             rf"every below {n}"):
            simulate_batch([machine], trajectory, settle=0.0, every=every)
    assert simulate_batch([machine], trajectory, settle=0.0, every=n - 1)["t"].tolist() == [0.0, trajectory.t[-1]]


def test_the_measured_reference_hold_and_settle_refuse_bad_arguments_naming_them(monkeypatch):
    # a servo period of 0 was an OverflowError (NaN: "cannot convert float NaN to integer"), a hold of 1e9 s a
    # MemoryError of 14.6 TiB, default_settle of a name an AttributeError
    t = np.arange(10) * 1e-3
    trace = Trace(t, t[:, None], t[:, None], ("x",), force={"x": np.ones(10)})
    for call in (measured_reference, measured_force):
        for period in (0.0, float("nan"), -1e-3):
            with pytest.raises(ValueError, match="servo_period must be"):
                call(trace, period)
    reference = measured_reference(trace, 1e-3)
    still = Trajectory(reference.t, np.zeros((10, 1)), np.zeros((10, 1)), np.zeros((10, 1)), np.zeros(10))
    monkeypatch.setattr(_memory, "available", lambda: 2**30)
    with pytest.raises(ValueError, match=r"a hold of 1e\+09 s: at dt = 0.001 s that is 1e\+12 samples"):
        still.held(1e9)
    assert len(still.held(0.0025)) == 13
    with pytest.raises(TypeError, match="machine must be a Machine"):
        default_settle("demo_mill")


def test_a_bow_the_path_runs_beyond_the_span_of_is_said_with_its_extrapolated_size():
    """A straightness is a bow over its guideway's travel (start_mm .. start_mm + span_mm): a path outside it got the
    parabola extrapolated without a word (a 5 µm bow over 500 .. 600 mm, the path at -2 .. 2 mm: 604 µm). It is said,
    with the size there from the bow's formula; a bow the path stays within says nothing."""
    from contoursim.effects import Effect
    from contoursim.model import Model

    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.iso230_4_circle(2.0, direction="ccw")
    reference = sample(path, plan(path, feed=10.0, accel=500.0), DT)
    low, high = reference.position[:, 0].min(), reference.position[:, 0].max()
    u = 2.0 * (np.array([low, high]) - 550.0) / 100.0
    beyond = float(np.abs(5.0 * (1.0 - u**2)).max())  # [µm]
    off = Effect("straightness", "x", peak_um=5.0, span_mm=100.0, start_mm=500.0, error_direction="y")
    with pytest.warns(ContoursimWarning, match=rf"straightness.x: axis x runs over -2 .. 2 mm, beyond the bow's span "
                                               rf"500 .. 600 mm .* up to {beyond:.4g} µm for a peak_um of 5"):
        simulate(Model(machine, (off,)), reference)
    within = Effect("straightness", "x", peak_um=5.0, span_mm=100.0, start_mm=-50.0, error_direction="y")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContoursimWarning)
        simulate(Model(machine, (within,)), reference)


def test_a_tool_the_geometry_puts_beyond_any_travel_is_refused_naming_the_effects():
    """A bow extrapolated a million mm beyond its span puts the tool 2e6 mm away: refused naming the effects, not
    the contour error's array index."""
    from contoursim.effects import Effect
    from contoursim.model import Model

    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.iso230_4_circle(2.0, direction="ccw")
    reference = sample(path, plan(path, feed=10.0, accel=500.0), DT)
    far = Effect("straightness", "x", peak_um=5.0, span_mm=100.0, start_mm=1e6, error_direction="y")
    with pytest.warns(ContoursimWarning), pytest.raises(
            ValueError, match=r"^the tool position reaches -2.000.e\+06 mm on y at t = 0 s, beyond ±1e\+06 mm, the axes "
                              r"within it: the geometric effects \(straightness.x\)"):
        simulate(Model(machine, (far,)), reference)


def test_a_loop_a_structural_mode_makes_diverge_names_the_models_loop_effects():
    """Nearly all the axis's mass on the mode's spring (mass_ratio 0.99): the velocity loop, tuned for the whole
    mass, drives a carriage of a hundredth of it and diverges. The kernel's message named the axis alone."""
    from contoursim.effects import Effect
    from contoursim.exceptions import UnstableLoopError
    from contoursim.model import Model

    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=40.0, **AXIS)}, DT)
    path = paths.iso230_4_circle(2.0, direction="ccw")
    reference = sample(path, plan(path, feed=10.0, accel=500.0), DT)
    mode = Effect("vibration", "x", freq_hz=80.0, damping_ratio=0.05, mass_ratio=0.99)
    with pytest.raises(UnstableLoopError, match=r"^the simulation of axis 'x' diverged .* \(the model's loop effects: "
                                                r"vibration.x\)$"):
        simulate(Model(machine, (mode,)), reference)


def test_a_screw_too_soft_to_carry_the_motors_motion_is_said():
    """A compliant screw of 1e-12 N/µm (inside its range): the motor follows its command, the table does not move,
    and the run reported its errors without a word. It says so; a real screw (150 N/µm) says nothing."""
    dt = 5e-4  # the fault's machine file's period
    path = paths.iso230_4_circle(2.0, direction="ccw")
    reference = sample(path, plan(path, feed=10.0, accel=500.0), dt)

    def run(stiffness):
        x = AxisServo(kp=40.0, motor_mass=100.0, screw_stiffness=stiffness, **AXIS)
        return simulate(Machine({"x": x, "y": AxisServo(kp=40.0, **AXIS)}, dt), reference)

    with pytest.warns(ContoursimWarning, match=r"^axis x was commanded over 4 mm and its table moved .* mm: its screw "
                                               r"\(screw_stiffness_N_per_um = 1e-12, 4e-09 N stretched over the whole "
                                               r"command\) does not carry the motor's motion to it$"):
        run(1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContoursimWarning)
        run(150.0)
