"""AxisServo: plant, loops and margins against hand-derived closed forms and python-control."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import control as ct
import numpy as np
import pytest

from contoursim import servo as servo_module
from contoursim.exceptions import UnstableLoopError
from contoursim.servo import AxisServo, zoh

ROOT = Path(__file__).resolve().parents[1]

# A ball-screw axis: 300 kg, 900 N/A, velocity loop crossing over at kv·kf/m = 600 rad/s.
MASS, KF, KV = 300.0, 900.0, 200.0
W_V = KV * KF / MASS  # [rad/s]
ELECTRICAL = dict(inductance=5e-3, resistance=1.2, kc=5e-3 * 2 * np.pi * 800, ti_current=5e-3 / 1.2)


def axis(**kw):
    return AxisServo(**{**dict(mass=MASS, force_constant=KF, kv=KV), **kw})


def response(sys, w):
    return ct.frequency_response(sys, np.atleast_1d(w)).complex.ravel()


# --- plant and its discretisation ------------------------------------------------------------


def test_plant_units_steady_velocity_per_amp():
    # Constant current i against viscous damping c: kf·i = c·v  ->  v = kf·i/c [m/s] = 1000·kf/c [mm/s per A].
    c = 4000.0
    velocity_per_amp = response(axis(damping=c).plant()[1, 0], 1e-7)[0]  # the plant at DC
    assert velocity_per_amp == pytest.approx(1000.0 * KF / c, rel=1e-6)


def test_electrical_plant_steady_state_with_back_emf():
    # Constant voltage u: di/dt = 0 and dv/dt = 0 give  kf·i = c·v/1000 and u = R·i + kf·v/1000.
    c, R = 4000.0, 1.2
    servo = axis(damping=c, **ELECTRICAL)
    v = response(servo.plant()[1, 0], 1e-7)[0].real  # per volt at DC [mm/s]
    i = response(servo.plant()[2, 0], 1e-7)[0].real  # per volt at DC [A]
    assert KF * i == pytest.approx(c * v / 1000.0, rel=1e-6)
    assert R * i + KF * v / 1000.0 == pytest.approx(1.0, rel=1e-6)


def test_zoh_double_integrator_closed_form():
    dt = 1e-3
    Ad, Bd = zoh(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [3.0]]), dt)
    np.testing.assert_allclose(Ad, [[1.0, dt], [0.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(Bd.ravel(), [3.0 * dt**2 / 2, 3.0 * dt], rtol=1e-12)


@pytest.mark.parametrize("extra", [dict(damping=2500.0), dict(damping=2500.0, **ELECTRICAL)])
def test_discrete_plant_equals_python_control_zoh(extra):
    servo, dt = axis(**extra), 1e-4
    mine = servo.discretize(dt).plant
    ref = ct.sample_system(servo.plant(), dt, method="zoh")
    np.testing.assert_allclose(mine.A, ref.A, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(mine.B, ref.B, rtol=1e-12, atol=1e-18)
    assert mine.dt == dt


@pytest.mark.parametrize(
    "gain, ti, block",
    [(KV / 1000, 0.01, "velocity_controller"), (ELECTRICAL["kc"], ELECTRICAL["ti_current"], "current_controller")],
)
def test_discrete_pi_is_tustin(gain, ti, block):
    dt = 1e-4
    d = axis(ti=0.01, **ELECTRICAL).discretize(dt)
    continuous = ct.tf([gain * ti, gain], [ti, 0])  # k·(1 + 1/(ti·s))
    ref = ct.sample_system(continuous, dt, method="tustin")
    w = np.logspace(0, np.log10(np.pi / dt) - 0.01, 7)
    np.testing.assert_allclose(response(getattr(d, block), w), response(ref, w), rtol=1e-10)


def test_pure_p_velocity_controller_has_no_state():
    d = axis().discretize(1e-4)
    assert d.velocity_controller.nstates == 0
    assert d.velocity_controller.D[0, 0] == pytest.approx(KV / 1000)


# --- closed loops: hand-derived transfer functions -------------------------------------------


def test_velocity_loop_first_order():
    # P velocity loop, no damping: L = W_V/s, closed loop W_V/(s + W_V).
    w = np.array([10.0, W_V, 5000.0])
    np.testing.assert_allclose(response(axis().velocity_loop(), w), W_V / (1j * w + W_V), rtol=1e-10)


def test_closed_loop_p_p_second_order():
    # T = kp·W_V / (s² + W_V·s + kp·W_V);  S = 1 - T.
    kp, w = 40.0, np.array([1.0, 40.0, 300.0])
    s = 1j * w
    T = kp * W_V / (s**2 + W_V * s + kp * W_V)
    servo = axis(kp=kp)
    np.testing.assert_allclose(response(servo.closed_loop(), w), T, rtol=1e-10)
    np.testing.assert_allclose(response(servo.sensitivity(), w), 1 - T, rtol=1e-10)


def test_full_feedforward_makes_p_p_loop_exact():
    # vff = aff = 1, no damping: (s² + W_V s + kp W_V)(x - r) = 0, so T = 1 at every frequency.
    w = np.array([1.0, 100.0, 1000.0])
    np.testing.assert_allclose(response(axis(vff=1.0, aff=1.0).closed_loop(), w), 1.0, rtol=1e-9)


def test_velocity_feedforward_alone():
    # vff = 1: T = W_V (s + kp) / (s² + W_V s + kp W_V); without feedforward the paths are off.
    kp, w = 40.0, np.array([1.0, 40.0, 300.0])
    s = 1j * w
    servo = axis(kp=kp, vff=1.0)
    den = s**2 + W_V * s + kp * W_V
    np.testing.assert_allclose(response(servo.closed_loop(), w), W_V * (s + kp) / den, rtol=1e-10)
    np.testing.assert_allclose(response(servo.closed_loop(feedforward=False), w), kp * W_V / den, rtol=1e-10)


def test_bandwidth_of_second_order_loop():
    kp = 40.0
    wn, zeta = np.sqrt(kp * W_V), W_V / (2 * np.sqrt(kp * W_V))
    wb = wn * np.sqrt(1 - 2 * zeta**2 + np.sqrt((1 - 2 * zeta**2) ** 2 + 1))
    assert axis(kp=kp).bandwidth() == pytest.approx(wb / (2 * np.pi), rel=1e-4)


# --- margins ---------------------------------------------------------------------------------


def test_margins_continuous_closed_form():
    # Velocity: L = W_V/s -> crossover W_V, 90°. Position: L = kp W_V/(s (s + W_V)),
    # crossover where ω²(ω² + W_V²) = (kp W_V)², phase margin 90° - atan(ω/W_V).
    kp = 40.0
    m = axis(kp=kp).margins()
    assert m["velocity"]["gain_crossover"] == pytest.approx(W_V, rel=1e-6)
    assert m["velocity"]["phase_margin"] == pytest.approx(90.0, abs=1e-6)
    w2 = (-(W_V**2) + np.sqrt(W_V**4 + 4 * (kp * W_V) ** 2)) / 2
    wc = np.sqrt(w2)
    assert m["position"]["gain_crossover"] == pytest.approx(wc, rel=1e-6)
    assert m["position"]["phase_margin"] == pytest.approx(90.0 - np.degrees(np.arctan(wc / W_V)), abs=1e-4)


def test_margins_sampled_velocity_loop_include_zoh_delay():
    # ZOH of W_V/s: L(z) = W_V dt/(z - 1); on z = e^{jωdt}: |L| = W_V dt / (2 sin(ωdt/2)),
    # phase -90° - ωdt/2. Crossover ω_c = (2/dt) asin(W_V dt/2), phase margin 90° - ω_c dt/2.
    dt = 2e-4
    wc = 2 / dt * np.arcsin(W_V * dt / 2)
    m = axis().margins(dt)["velocity"]
    assert m["gain_crossover"] == pytest.approx(wc, rel=1e-6)
    assert m["phase_margin"] == pytest.approx(90.0 - np.degrees(wc * dt / 2), abs=1e-4)
    # gain margin: phase -180° at the Nyquist frequency, where |L| = W_V dt / 2
    assert m["gain_margin"] == pytest.approx(2 / (W_V * dt), rel=1e-4)


@pytest.mark.parametrize("extra", [dict(ti=0.01, damping=2000.0), dict(ti=0.01, **ELECTRICAL)])
def test_margins_match_dense_frequency_sweep(extra):
    # Crossovers found by brute force on 20,000 frequencies of python-control's own loop response.
    from contoursim.servo import _blocks, _loop_gains

    dt = 1e-4
    servo = axis(**extra)
    m = servo.margins(dt)
    for name, loop in _loop_gains(_blocks(servo, dt)).items():
        w = np.logspace(-1, np.log10(np.pi / dt) - 1e-9, 20_000)
        L = response(loop, w)
        i = np.flatnonzero(np.diff(np.sign(np.abs(L) - 1)))
        assert i.size == 1, name
        assert m[name]["gain_crossover"] == pytest.approx(w[i[0]], rel=1e-3)
        assert m[name]["phase_margin"] == pytest.approx(180 + np.degrees(np.angle(L[i[0]])), abs=0.02)
        assert m[name]["stable"]


def test_check_accepts_typical_axes():
    assert axis().check(2e-4)["position"]["stable"]
    assert set(axis(ti=0.01, **ELECTRICAL).check(1e-4)) == {"current", "velocity", "position"}


# --- bad input -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(mass=-1.0), "mass"),
        (dict(mass=0.0), "mass"),
        (dict(force_constant=float("nan")), "force_constant"),
        (dict(kv=0.0), "kv"),
        (dict(kp=-40.0), "kp"),
        (dict(ti=0.0), "ti"),
        (dict(damping=-1.0), "damping"),
        (dict(current_limit=0.0), "current_limit"),
        (dict(vff=1.5), "vff"),
        (dict(aff=-0.1), "aff"),
        (dict(resistance=1.0), "inductance"),
        (dict(inductance=5e-3, resistance=1.0, ti_current=1e-3), "kc"),
        (dict(inductance=-5e-3, resistance=1.0, kc=10.0, ti_current=1e-3), "inductance"),
    ],
)
def test_bad_parameters_name_the_parameter(kw, name):
    with pytest.raises(ValueError, match=name):
        axis(**kw)


def test_a_wrong_type_is_a_type_error():
    with pytest.raises(TypeError, match="kv must be a number, got 'fast'"):
        axis(kv="fast")


def test_mass_is_required():
    with pytest.raises(TypeError, match="mass"):
        AxisServo(force_constant=KF, kv=KV)


def test_dt_too_long_names_dt_and_gain():
    # velocity crossover 95 Hz: needs dt <= 1/(8·95 Hz) = 1.3 ms
    with pytest.raises(ValueError, match=r"dt = 0\.005 s .*velocity loop of axis 'y'.*kv") as err:
        axis().check(5e-3, axis="y")
    assert not isinstance(err.value, UnstableLoopError)
    with pytest.raises(ValueError, match="dt must be positive"):
        axis().check(0.0)


def test_badly_damped_position_gain_names_axis_loop_and_margins():
    # kp = 2000 1/s against a 600 rad/s velocity loop: phase margin about 25°
    message = r"position loop of axis 'z' is badly damped.*phase margin 2\d\.\d deg.*kp"
    with pytest.raises(UnstableLoopError, match=message) as err:
        axis(kp=2000.0).check(2e-4, axis="z")
    assert err.value.margins["phase_margin"] < 30.0
    assert err.value.margins["stable"]


def test_unstable_position_gain():
    # P-P sampled position loop: gain margin 10 at kp = 1000 (phase -180° at 2475 rad/s), so kp = 12000
    # is unstable, while its continuous crossover (430 Hz) still passes the sampling rule.
    assert axis(kp=1000.0).margins(2e-4)["position"]["gain_margin"] == pytest.approx(10.0, rel=1e-3)
    with pytest.raises(UnstableLoopError, match=r"position loop of axis 'x' is unstable") as err:
        axis(kp=12000.0).check(2e-4)
    assert not err.value.margins["stable"]


def test_a_loop_gain_above_1_up_to_nyquist_is_told_to_come_down():
    """kv 1000 times too high has no gain crossover below Nyquist, as a loop too weak has none: it was told to raise kv."""
    message = (r"velocity loop of axis 'x' is unstable at dt = 0.0002 s: gain margin 0.0333, no gain crossover \(the loop "
               r"gain stays above 1 up to the Nyquist frequency\), damping ratio -0.792 \(kv = 100000\): lower kv, or check")
    with pytest.raises(UnstableLoopError, match=message):
        axis(kv=1e5).check(2e-4)


def test_sampled_instability_is_caught():
    # Continuous loops are fine (crossover 150 Hz < 1/4 Nyquist), but a PI integral time far
    # shorter than the velocity loop's time constant destabilises it.
    with pytest.raises(UnstableLoopError, match=r"velocity loop of axis 'x' is (unstable|badly damped).*ti") as err:
        axis(ti=2e-4).check(2e-4)
    assert err.value.margins is not None


@pytest.mark.parametrize("extra", [dict(), dict(ti=0.01, damping=2000.0), dict(ti=0.01, **ELECTRICAL)])
@pytest.mark.parametrize("dt", [None, 1e-4])
def test_margins_equal_python_control_stability_margins(extra, dt):
    from contoursim.servo import _blocks, _frequency_grid, _loop_gains, _loop_response

    servo = axis(**extra)
    mine = servo.margins(dt)
    for name, loop in _loop_gains(_blocks(servo, dt or 0)).items():
        w = _frequency_grid(loop)
        L = _loop_response(loop)(w)
        s = np.exp(1j * w * dt) if dt else 1j * w
        # python-control's own evaluation of the state space, to rounding: far past crossover, |L| ~ 1e-12 of its peak
        np.testing.assert_allclose(L, loop(s), rtol=1e-8, atol=1e-14 * np.abs(L).max())
        with np.errstate(divide="ignore"):
            gm, pm, _, wpc, wgc, _ = ct.stability_margins((np.abs(L), np.angle(L, deg=True), w), method="frd")
        m = mine[name]
        assert m["gain_margin"] == pytest.approx(gm, rel=1e-5), name
        assert m["phase_margin"] == pytest.approx(pm, abs=1e-4), name
        assert m["gain_crossover"] == pytest.approx(wgc, rel=1e-5), name
        np.testing.assert_allclose(m["phase_crossover"], wpc, rtol=1e-5)  # NaN when the phase never reaches -180°


def test_loop_analysis_runs_once_per_servo_and_period(monkeypatch):
    calls = []
    loop_gains = servo_module._loop_gains
    monkeypatch.setattr(servo_module, "_loop_gains", lambda blocks: calls.append(1) or loop_gains(blocks))
    servo = axis(kv=KV * 1.01)  # a servo no other test analysed
    first = servo.check(2e-4, axis="x")
    assert len(calls) == 2  # the continuous loop (sampling rule) and the sampled loop
    first["position"]["phase_margin"] = -1.0  # a caller editing its copy changes nothing
    again = axis(kv=KV * 1.01).check(2e-4, axis="y")  # an equal servo under another axis name
    assert len(calls) == 2 and again["position"]["phase_margin"] > 30.0
    servo.check(1e-4)
    assert len(calls) == 3


def test_an_analysis_is_stored_and_a_later_process_reads_it_back_without_python_control(tmp_path, monkeypatch):
    monkeypatch.setenv("CONTOURSIM_CACHE_DIR", str(tmp_path))
    servo_module._margins.cache_clear()  # analysed in this process, not remembered from another test
    servo, dt = axis(kp=37.0, ti=0.011, **ELECTRICAL), 2e-4
    analysed = servo_module.margins(servo, dt)
    assert len(list((tmp_path / "margins").glob("*.json"))) == 1
    code = ("import json, sys\nfrom contoursim.servo import AxisServo, margins\n"
            f"m = margins(AxisServo(**{dataclasses.asdict(servo)!r}), {dt!r})\n"
            "print(json.dumps([m, 'control' in sys.modules]))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                          capture_output=True, text=True, timeout=120, check=True)
    stored, imported_control = json.loads(done.stdout)
    assert stored == json.loads(json.dumps(analysed)) and not imported_control  # the same figures, no analysis
    # another parameter, or a damaged file, is analysed anew
    other = axis(kp=38.0, ti=0.011, **ELECTRICAL)
    assert servo_module.margins(other, dt)["position"]["gain_crossover"] != analysed["position"]["gain_crossover"]
    assert len(list((tmp_path / "margins").glob("*.json"))) == 2
    for stored_file in (tmp_path / "margins").glob("*.json"):
        stored_file.write_text("{")
    servo_module._margins.cache_clear()
    assert servo_module.margins(servo, dt) == analysed


@pytest.mark.parametrize("weak, old", [
    (dict(kv=1e-6, ti=0.016, damping=500.0), "raise kp"),  # a PI velocity loop of no strength: kp was to be raised
    (dict(kv=1.0), "lower kp (or make the velocity loop faster)"),
])
def test_a_position_loop_failing_for_a_slow_velocity_loop_is_told_to_raise_kv_or_lower_kp_and_either_helps(weak, old):
    """The advice follows from the margins: a velocity loop crossing over below 4 kp is the position loop's trouble."""
    import re

    from contoursim.servo import CASCADE_RATIO

    servo = AxisServo(mass=300.0, force_constant=942.0, kp=40.0, **weak)
    with pytest.raises(UnstableLoopError, match=r"the position loop of axis 'x' is") as err:
        servo.check(2e-4)
    message = str(err.value)
    assert old not in message and "the velocity loop is too slow for it" in message and "raise kv" in message
    velocity = servo.margins(2e-4)["velocity"]["gain_crossover"]
    assert not velocity >= CASCADE_RATIO * servo.kp  # the margins say so: the velocity loop is below 4 kp (or never 1)
    dataclasses.replace(servo, kv=80.0).check(2e-4)  # raising kv to a velocity loop of 40 Hz, or ...
    lower = re.search(r"lower kp, to ([0-9.e+-]+) 1/s or less", message)
    if lower:  # ... lowering kp as far as said, each passes the check
        dataclasses.replace(servo, kp=float(lower.group(1))).check(2e-4)


def test_the_kp_a_refusal_says_to_lower_to_is_the_checks_own_bound():
    """kp 500 on a velocity loop of 41 Hz was told to go to 64.6 1/s or less (a velocity loop 4 times faster, the rule
    of thumb), where 400 passes the check (an outside probe): the bound said passes, a tenth of a percent above fails."""
    import re

    servo = AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=500.0)
    with pytest.raises(UnstableLoopError, match=r"the position loop of axis 'x' is badly damped") as err:
        servo.check(2e-4)
    said = re.search(r"lower kp, to ([0-9.e+-]+) 1/s or less \(the check's bound; a velocity loop 4 times faster, the "
                     r"rule of thumb, allows ([0-9.]+) 1/s\)", str(err.value))
    assert said, str(err.value)
    bound, rule = float(said.group(1)), float(said.group(2))
    assert rule < 100.0 < 400.0 < bound < 500.0
    dataclasses.replace(servo, kp=bound).check(2e-4)
    with pytest.raises(UnstableLoopError):
        dataclasses.replace(servo, kp=1.01 * bound).check(2e-4)


def test_a_pi_velocity_loop_crossing_below_its_integral_corner_is_told_to_raise_kv_not_lower_it():
    """At kv = 1 the PI loop crosses over at 2.3 Hz, below its corner 1/(2π ti) = 9.9 Hz: lowering kv made it worse."""
    servo = AxisServo(mass=300.0, force_constant=942.0, kv=1.0, ti=0.016, kp=1.0)
    with pytest.raises(UnstableLoopError, match=r"the velocity loop of axis 'x' is badly damped") as err:
        servo.check(2e-4)
    assert "below the integral action's corner 1/(2π·ti) = 9.947 Hz: raise kv, or lengthen ti." in str(err.value)
    assert servo.margins(2e-4)["velocity"]["gain_crossover"] * servo.ti < 1.0
    dataclasses.replace(servo, kv=30.0).check(2e-4)  # raising kv helps, ...
    dataclasses.replace(servo, ti=0.2).check(2e-4)  # ... and so does a longer ti
    with pytest.raises(UnstableLoopError):
        dataclasses.replace(servo, kv=0.5).check(2e-4)  # lowering it, the old advice, does not


@pytest.mark.parametrize("extra, words", [
    (dict(current_bandwidth_hz=1e-3), "the current loop is too slow for it (bandwidth 0.001 Hz, below its crossover "
                                      "0.7361 Hz): raise current_bandwidth_hz."),
    (dict(**ELECTRICAL | dict(kc=1e-3)), "the current loop is too slow for it"),
])
def test_a_velocity_loop_failing_for_a_slow_current_loop_is_told_to_speed_up_the_current_loop(extra, words):
    """A current loop of 1 mHz lags the velocity loop by nearly 90°: raising kv or lengthening ti, as it was told, won't."""
    servo = AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, **extra)
    with pytest.raises(UnstableLoopError, match=r"the velocity loop of axis 'x' is") as err:
        servo.check(5e-4)
    assert words in str(err.value) and "lengthen ti" not in str(err.value)


def test_an_integral_time_too_short_for_the_period_is_named_not_the_period_or_kv():
    """ti = 1 µs lifts the velocity loop's crossover to 2.5 kHz: it was told to shorten dt or lower kv."""
    from contoursim.servo import SamplingError

    with pytest.raises(SamplingError, match=r"ti = 1e-06 s is too short for the velocity loop of axis 'x' at dt = "
                                            r"0.0005 s: its integral action lifts the crossover to 2523 Hz.*"
                                            r"Lengthen ti, or use dt <= 4.96e-05 s\.$") as err:
        AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=1e-6, kp=40.0).check(5e-4)
    assert err.value.parameter == "ti"
    with pytest.raises(SamplingError, match=r"dt = 0.01 s is too long.*or lower kv = 80\.$") as err:
        AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0).check(1e-2)
    assert err.value.parameter == "dt"


def test_a_crossover_no_drive_has_names_the_mass_and_force_constant():
    """mass_kg = 1e-6 (a millionth of the mass) was told to use dt <= 1e-11 s at servo_period_ms's line, the mass never
    named (an outside probe)."""
    from contoursim.servo import SamplingError

    with pytest.raises(SamplingError, match=r"its crossover 1.199e\+10 Hz is above 1/4 of the Nyquist frequency \(625 "
                                            r"Hz\) \(a crossover no drive has: check the mass, 1e-06 kg, and "
                                            r"force_constant, 942 N/A, for their units\)") as err:
        AxisServo(mass=1e-6, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, damping=500.0).check(2e-4)
    assert err.value.parameter == "mass"  # a machine file's refusal at mass_kg's line, not servo_period_ms's
