"""The stepping kernel against python-control's simulation and hand-derived steady states."""

import control as ct
import numpy as np
import pytest

from contoursim.exceptions import UnstableLoopError
from contoursim.kernel import run
from contoursim.servo import AxisServo

MASS, KF, KV = 300.0, 900.0, 200.0
ELECTRICAL = dict(inductance=5e-3, resistance=1.2, kc=5e-3 * 2 * np.pi * 800, ti_current=5e-3 / 1.2)
DT = 1e-4


def axis(**kw):
    return AxisServo(**{**dict(mass=MASS, force_constant=KF, kv=KV), **kw})


# --- linear response = python-control's simulation of the discrete interconnection -----------


def reference_loop(d):
    """The sampled cascade wired here from the discrete blocks of `discretize` (not from servo.py's wiring)."""
    s, dt = d.servo, d.dt

    def gain(k, inp, out):
        return ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[k]], dt, inputs=inp, outputs=out)

    amps_per_accel = s.aff * s.mass / (1000.0 * s.force_constant)  # aff·m·a/kf with a in m/s²
    blocks = [
        d.plant,
        d.velocity_controller,
        ct.summing_junction(["xr", "-x"], "ex"),
        gain(s.kp, "ex", "vp"),
        gain(s.vff, "vr", "vf"),
        ct.summing_junction(["vp", "vf", "-v"], "e_v"),
        gain(amps_per_accel, "ar", "iff"),
        ct.summing_junction(["i_pi", "iff"], "i_cmd"),
    ]
    if d.current_controller is not None:
        blocks += [d.current_controller, ct.summing_junction(["i_cmd", "-i"], "e_i")]
    return ct.interconnect(blocks, inplist=["xr", "vr", "ar"], outlist=["x", "v", "i_cmd"])


def wiggly_reference(n, dt, phase):
    t = np.arange(n) * dt
    w = 2 * np.pi * np.array([3.0, 17.0])
    pos = 2.0 + 5.0 * np.sin(w[0] * t + phase) + 0.3 * np.sin(w[1] * t) + 40.0 * t**2
    vel = 5.0 * w[0] * np.cos(w[0] * t + phase) + 0.3 * w[1] * np.cos(w[1] * t) + 80.0 * t
    acc = -5.0 * w[0] ** 2 * np.sin(w[0] * t + phase) - 0.3 * w[1] ** 2 * np.sin(w[1] * t) + 80.0
    return t, pos, vel, acc


def test_linear_response_equals_python_control():
    servos = [
        axis(kp=40.0, damping=1500.0),  # P-P
        axis(kp=35.0, ti=0.01, damping=1500.0, vff=0.9),  # P-PI, velocity feedforward
        axis(kp=45.0, ti=0.01, damping=1500.0, vff=1.0, aff=0.7, **ELECTRICAL),  # P-PI-PI, both feedforwards
    ]
    n = 3000
    refs = [wiggly_reference(n, DT, phase) for phase in (0.0, 1.0, 2.0)]
    t = refs[0][0]
    pos, vel, acc = (np.column_stack([r[j] for r in refs]) for j in (1, 2, 3))
    result = run(servos, DT, pos, vel, acc)
    np.testing.assert_array_equal(result.t, t)
    assert not result.saturated.any()
    for a, servo in enumerate(servos):
        loop = reference_loop(servo.discretize(DT))
        x0 = np.zeros(loop.nstates)
        x0[loop.state_labels.index("plant_x")] = pos[0, a]  # the kernel starts at rest at the first command
        ref = ct.forced_response(loop, t, np.vstack([pos[:, a], vel[:, a], acc[:, a]]), X0=x0).outputs
        for got, want in zip((result.position[:, a], result.velocity[:, a], result.current[:, a]), ref):
            assert np.max(np.abs(got - want)) <= 1e-9 * np.max(np.abs(want))


# --- steady-state following error on a ramp --------------------------------------------------

V = 50.0  # ramp speed [mm/s] (3 m/min)
C = 3000.0  # viscous damping [N·s/m]


def ramp_error(servo, n=20000):
    t = np.arange(n) * DT
    pos = (V * t)[:, None]
    result = run([servo], DT, pos, np.full_like(pos, V), np.zeros_like(pos))
    return pos[-1, 0] - result.position[-1, 0]


@pytest.mark.parametrize("kp", [20.0, 40.0])
def test_ramp_error_p_pi_is_v_over_kp(kp):
    # The integrator supplies the damping current, so the velocity error is zero: kp·e = v.
    assert ramp_error(axis(kp=kp, ti=0.01, damping=C)) == pytest.approx(V / kp, rel=1e-9)


@pytest.mark.parametrize("damping", [0.0, C])
def test_ramp_error_p_p_with_damping(damping):
    # Steady ramp: the current c·v/kf (damping force / force constant) must come from the velocity
    # error: (kv/1000)·(kp·e - v) = c·v/(1000·kf)  ->  e = (v/kp)·(1 + c/(kf·kv)); v/kp when c = 0.
    expected = V / 40.0 * (1 + damping / (KF * KV))
    assert ramp_error(axis(kp=40.0, damping=damping)) == pytest.approx(expected, rel=1e-9)


def test_ramp_error_vanishes_with_velocity_feedforward_and_pi():
    assert abs(ramp_error(axis(kp=40.0, ti=0.01, damping=C, vff=1.0))) < 1e-9


def test_ramp_error_p_p_with_velocity_feedforward():
    # vff = 1 removes v from the velocity error; only the damping current remains: e = (v/kp)·c/(kf·kv).
    assert ramp_error(axis(kp=40.0, damping=C, vff=1.0)) == pytest.approx(V / 40.0 * C / (KF * KV), rel=1e-9)


# --- steady-state circle ---------------------------------------------------------------------


@pytest.mark.parametrize("extra", [dict(damping=C), dict(ti=0.01, damping=C), dict(ti=0.01, vff=0.5, aff=0.5)])
@pytest.mark.parametrize("radius, feed", [(5.0, 2000.0), (10.0, 6000.0), (50.0, 10000.0)])
def test_circle_radius_follows_closed_loop_gain(extra, radius, feed):
    servo = axis(kp=40.0, **extra)
    w = feed / 60.0 / radius  # [rad/s]
    t = np.arange(int(2.0 / DT)) * DT
    u = np.column_stack([np.cos(w * t), np.sin(w * t)])
    du = np.column_stack([-np.sin(w * t), np.cos(w * t)])
    result = run([servo, servo], DT, radius * u, radius * w * du, -radius * w**2 * u)
    gain = np.abs(ct.frequency_response(servo.closed_loop(), [w]).complex.ravel()[0])
    settled = np.hypot(*result.position[-500:].T)
    np.testing.assert_allclose(settled, radius * gain, rtol=1e-3)


# --- a known external force -------------------------------------------------------------------


def pulses(n, level, period):
    """A force of `level` [N] on for the second half of every `period` samples, shape (n, 1)."""
    return level * ((np.arange(n) % period) >= period // 2).astype(float)[:, None]


@pytest.mark.parametrize("force", [-178.0, 60.0])
def test_external_force_at_standstill_p_p_and_p_pi(force):
    # At rest the force must be balanced by the drive: kf·i + F = 0. P-P: the current comes from the position error
    # through both gains, i = (kv/1000)·kp·(x_ref - x), so x - x_ref = 1000·F/(kf·kv·kp) [mm] (damping plays no
    # part at rest); P-PI: the integrator supplies it and the error vanishes.
    n = 20000
    ref = np.full((n, 1), 3.0)
    f = np.full((n, 1), force)
    p_p = run([axis(kp=40.0, damping=C)], DT, ref, np.zeros_like(ref), np.zeros_like(ref), force=f)
    assert p_p.position[-1, 0] - 3.0 == pytest.approx(1000.0 * force / (KF * KV * 40.0), rel=1e-9)
    assert p_p.current[-1, 0] == pytest.approx(-force / KF, rel=1e-9)
    p_pi = run([axis(kp=40.0, ti=0.01, damping=C)], DT, ref, np.zeros_like(ref), np.zeros_like(ref), force=f)
    assert abs(p_pi.position[-1, 0] - 3.0) < 1e-9
    assert p_pi.current[-1, 0] == pytest.approx(-force / KF, rel=1e-9)


def test_external_force_response_equals_python_control():
    # The sampled P-PI loop wired in python-control with the force as a second plant input, both inputs held over
    # the period (the plant sampled by ct.sample_system's own ZOH), driven by a moving reference and force pulses.
    servo = axis(kp=35.0, ti=0.01, damping=1500.0)
    d = servo.discretize(DT)
    n = 3000
    t, pos, vel, acc = wiggly_reference(n, DT, 0.5)
    force = pulses(n, 250.0, 400) - 80.0 * np.sin(2 * np.pi * 9.0 * t)[:, None]
    m, c = servo.mass, servo.damping
    plant = ct.sample_system(ct.ss([[0.0, 1.0], [0.0, -c / m]], [[0.0, 0.0], [1000.0 * KF / m, 1000.0 / m]], np.eye(2),
                                   np.zeros((2, 2)), inputs=["i_cmd", "F"], outputs=["x", "v"], states=["x", "v"]),
                             DT, "zoh", name="plant")  # fmt: skip
    kp = ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[servo.kp]], DT, inputs="ex", outputs="vp")
    loop = ct.interconnect([plant, d.velocity_controller, kp, ct.summing_junction(["xr", "-x"], "ex"),
                            ct.summing_junction(["vp", "-v"], "e_v"), ct.summing_junction(["i_pi"], "i_cmd")],
                           inplist=["xr", "F"], outlist=["x", "v", "i_cmd"])  # fmt: skip
    x0 = np.zeros(loop.nstates)
    x0[loop.state_labels.index("plant_x")] = pos[0]
    want = ct.forced_response(loop, t, np.vstack([pos, force[:, 0]]), X0=x0).outputs
    got = run([servo], DT, pos[:, None], vel[:, None], acc[:, None], force=force)
    no_force = run([servo], DT, pos[:, None], vel[:, None], acc[:, None])
    for signal, ref in zip((got.position, got.velocity, got.current), want):
        assert np.max(np.abs(signal[:, 0] - ref)) <= 1e-9 * np.max(np.abs(ref))
    assert np.max(np.abs(got.position - no_force.position)) > 1e-3  # the force moves the axis by µm, not rounding


def test_external_force_is_checked():
    ref = np.zeros((10, 2))
    with pytest.raises(ValueError, match=r"force must have shape \(10, 2\)"):
        run([axis(), axis()], DT, ref, ref, ref, force=np.zeros((10, 1)))
    bad = np.zeros((10, 2))
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match=r"force contains a non-finite value \(inf\) at index \(3, 1\)"):
        run([axis(), axis()], DT, ref, ref, ref, force=bad)


# --- saturation ------------------------------------------------------------------------------


def test_saturation_limit_constant_acceleration_and_anti_windup():
    # A 1 mm step demands kv/1000·kp·1 mm = 8 A; the limit is 0.5 A. Hand-checkable:
    # - the current command never exceeds the limit;
    # - while clamped, the undamped slide accelerates at exactly a = 1000·kf·limit/m:
    #   x = a t²/2, v = a t from the first step;
    # - this loop's linear step response does not overshoot, and with anti-windup neither
    #   does the saturated one (a wound-up integrator overshoots by about 0.28 mm here).
    limit, step = 0.5, 1.0
    ref = np.full((int(0.5 / DT), 1), step)
    ref[0] = 0.0
    servo = axis(kp=40.0, ti=0.01, current_limit=limit)
    result = run([servo], DT, ref, np.zeros_like(ref), np.zeros_like(ref))
    linear = run([axis(kp=40.0, ti=0.01)], DT, ref, np.zeros_like(ref), np.zeros_like(ref))

    assert np.all(np.abs(result.current) <= limit)
    n_sat = int(np.argmin(result.saturated[1:, 0])) + 1  # steps 1 .. n_sat-1 are clamped
    assert n_sat > 50 and result.saturated[1:n_sat, 0].all()
    np.testing.assert_array_equal(result.current[1:n_sat, 0], limit)
    a = 1000.0 * KF * limit / MASS
    t = (np.arange(1, n_sat + 1) - 1) * DT  # time since the first clamped step
    np.testing.assert_allclose(result.velocity[1 : n_sat + 1, 0], a * t, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.position[1 : n_sat + 1, 0], a * t**2 / 2, rtol=1e-9, atol=1e-15)

    assert linear.position.max() <= step * (1 + 1e-9)
    assert result.position.max() <= step * (1 + 1e-9)
    assert result.position[-1, 0] == pytest.approx(step, abs=1e-6)


def test_saturation_flags_only_where_clamped():
    ref = np.full((200, 1), 0.001)  # a 1 µm step: 0.008 A, far below the limit
    ref[0] = 0.0
    result = run([axis(current_limit=5.0)], DT, ref, np.zeros_like(ref), np.zeros_like(ref))
    assert not result.saturated.any()


# --- bad input -------------------------------------------------------------------------------


def test_reference_shapes_and_values_are_checked():
    servo = axis()
    pos = np.zeros((10, 2))
    with pytest.raises(ValueError, match=r"ref_pos must have shape \(N, 2\)"):
        run([servo, servo], DT, np.zeros((10, 3)), pos, pos)
    with pytest.raises(ValueError, match="ref_vel"):
        run([servo, servo], DT, pos, np.zeros((9, 2)), pos)
    bad = pos.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"ref_acc contains a non-finite value \(nan\) at index \(4, 1\)"):
        run([servo, servo], DT, pos, pos, bad)
    with pytest.raises(ValueError, match="dt must be positive"):
        run([servo, servo], -DT, pos, pos, pos)
    with pytest.raises(TypeError, match=r"servos\['y'\] must be an AxisServo"):
        run([servo, "fast"], DT, pos, pos, pos)
    with pytest.raises(TypeError, match="coupling must be a Coupling"):
        run([servo, servo], DT, pos, pos, pos, coupling="arc")


def test_loop_problems_name_the_axis():
    pos = np.zeros((10, 2))
    with pytest.raises(UnstableLoopError, match="position loop of axis 'c'"):
        run({"x": axis(), "c": axis(kp=2000.0)}, 2e-4, pos, pos, pos)
    with pytest.raises(ValueError, match="dt = 0.005 s is too long for the velocity loop of axis 'x'"):
        run([axis(), axis()], 5e-3, pos, pos, pos)


def test_the_knots_the_kernel_is_given_are_a_couplings_shape_as_its_docstring_says():
    from contoursim import kernel

    circle = np.column_stack([np.cos(np.linspace(0.0, 6.0, 50)), np.sin(np.linspace(0.0, 6.0, 50))])
    knots = kernel.Coupling("arc", circle, kp=10.0).knots
    assert knots.shape == (50, 4) and kernel._no_coupling()[1].shape[1] == 4
    assert f"``knots`` (M, {knots.shape[1]})" in kernel._variant.__doc__
