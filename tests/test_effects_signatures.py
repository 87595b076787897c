"""Each effect's signature on circles and lines, measured from the simulated tool positions.

Ballbar practice (ISO 230-4 Annex B): the radial deviation of the tool from
the nominal circle over the test circle, as a function of the angle of the
tool itself, fitted here with a few Fourier terms — code that knows nothing
of how the effects are modelled. Each run is compared with the same run of
the nominal machine, sample by sample, so what is left is the effect's
signature; it is checked against closed forms (squareness: Δr =
−(αR/2)·sin 2θ; scale error: Δr = R·k·cos²θ; command delay τ on Y: Δr =
∓(Rωτ/2)·sin 2θ; gain mismatch: the phase lag ω/Kp of each axis, ...).
"""

from functools import lru_cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim import paths
from contoursim.effects import Effect
from contoursim.feed import plan, sample
from contoursim.machine import Machine
from contoursim.model import Model
from contoursim.servo import AxisServo
from contoursim.simulation import simulate
from contoursim.traces import Trace

DT = 1e-3  # a coarse servo period: the loops cross over near 40 Hz
AXIS = dict(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, damping=500.0)
MACHINE = Machine({"x": AxisServo(**AXIS), "y": AxisServo(**AXIS)}, DT)
R = 10.0  # [mm]


@lru_cache
def _reference(key):
    """``("circle", direction, feed)``: an ISO 230-4 circle whose test circle starts at 45° (not at
    a reversal); ``("line",)``: 40 mm along X, centred on the origin."""
    if key[0] == "circle":
        path = paths.iso230_4_circle(R, direction=key[1], start_angle=np.pi / 4)
        return sample(path, plan(path, feed=key[2], accel=1000.0, jerk=5e4), DT)
    line = paths.line((-20.0, 0.0), (20.0, 0.0))
    return sample(line, plan(line, feed=50.0, accel=2000.0), DT)


@lru_cache
def _nominal(key):
    return simulate(MACHINE, _reference(key), settle=0.0).tool_position


def _deviation(effect, key):
    """Tool position with the effect minus without it [mm], shape (N, 2)."""
    return simulate(Model(MACHINE, (effect,)), _reference(key), settle=0.0).tool_position - _nominal(key)


def _polar(effect, direction, feed):
    """Angle of the tool and the effect's radial deviation [µm] over the test circle."""
    key = ("circle", direction, feed)
    keep = _reference(key).measuring
    nominal = _nominal(key)[keep]
    actual = nominal + _deviation(effect, key)[keep]
    theta = np.arctan2(actual[:, 1], actual[:, 0])
    return theta, 1e3 * (np.hypot(*actual.T) - np.hypot(*nominal.T))


def _harmonics(theta, dr):
    """Least-squares c0 + c1 cos θ + s1 sin θ + c2 cos 2θ + s2 sin 2θ [µm], as a dict."""
    basis = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    return dict(zip(("c0", "c1", "s1", "c2", "s2"), np.linalg.lstsq(basis, dr, rcond=None)[0]))


# -- geometric effects: shape independent of feed and direction ------------------------------


@pytest.mark.parametrize("direction", ["ccw", "cw"])
@pytest.mark.parametrize("feed", [20.0, 40.0])
def test_squareness_is_a_45_degree_ellipse_that_neither_flips_nor_depends_on_feed(direction, feed):
    alpha = 100.0  # [µrad]
    h = _harmonics(*_polar(Effect("squareness", "xy", angle_urad=alpha), direction, feed))
    assert h["s2"] == pytest.approx(-alpha * 1e-6 * R * 1e3 / 2, rel=0.01)  # −αR/2 [µm]
    assert abs(h["c2"]) < 0.01 * abs(h["s2"])


@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_scale_error_is_an_axis_aligned_ellipse(direction):
    ppm = 50.0
    h = _harmonics(*_polar(Effect("scale_error", "x", ppm=ppm), direction, 20.0))
    expected = R * ppm * 1e-6 * 1e3 / 2  # R·k·cos²θ = (Rk/2)(1 + cos 2θ) [µm]
    assert h["c2"] == pytest.approx(expected, rel=0.01)
    assert h["c0"] == pytest.approx(expected, rel=0.01)
    assert abs(h["s2"]) < 0.01 * expected


def test_cyclic_error_is_a_ripple_at_the_lead():
    amplitude, period = 2.0, 5.0  # [µm], [mm]
    dx = 1e3 * _deviation(Effect("cyclic_error", "x", amplitude_um=amplitude, period_mm=period), ("line",))[:, 0]
    x = _nominal(("line",))[:, 0]
    # amplitude spectrum over position, on a uniform position grid
    grid = np.linspace(-20.0, 20.0, 4001)
    order = np.argsort(x)
    ripple = np.interp(grid, x[order], dx[order])
    spectrum = 2 * np.abs(np.fft.rfft(ripple[:-1])) / (grid.size - 1)
    frequency = np.fft.rfftfreq(grid.size - 1, grid[1] - grid[0])
    peak = np.argmax(spectrum)
    assert 1 / frequency[peak] == pytest.approx(period, rel=1e-6)
    assert spectrum[peak] == pytest.approx(amplitude, rel=0.01)


def test_straightness_is_a_bow():
    peak, span = 5.0, 40.0  # the line runs over the whole travel, -20 .. 20 mm
    effect = Effect("straightness", "x", peak_um=peak, span_mm=span, start_mm=-20.0, error_direction="y")
    dy = 1e3 * _deviation(effect, ("line",))[:, 1]
    x = _nominal(("line",))[:, 0]
    coeffs = np.polyfit(x, dy, 2)
    assert np.abs(np.polyval(coeffs, x) - dy).max() < 1e-9  # a parabola ...
    chord = (np.polyval(coeffs, 20.0) + np.polyval(coeffs, -20.0)) / 2
    assert np.polyval(coeffs, 0.0) - chord == pytest.approx(peak, rel=1e-6)  # ... whose middle is peak off the chord
    assert chord == pytest.approx(0.0, abs=1e-9)  # and whose ends, the travel's, are on the line


@given(start=st.floats(-500.0, 500.0), span=st.floats(10.0, 2000.0), peak=st.floats(-15.0, 15.0),
       where=st.floats(0.0, 1.0), other=st.floats(-300.0, 300.0))
@settings(max_examples=60, deadline=None)
def test_straightness_is_zero_at_the_travel_ends_and_peak_in_its_middle_wherever_the_path_lies(start, span, peak, where, other):
    """The bow is the guideway's: a function of the axis's own position over its travel, not of the path."""
    effect = Effect("straightness", "x", peak_um=peak, span_mm=span, start_mm=start, error_direction="y")
    geometry = Model(MACHINE, (effect,)).geometry
    q = np.array([[start, other], [start + span, other], [start + span / 2, other], [start + where * span, -other]])
    dy = 1e3 * (geometry.tool_position(q, np.zeros(4), 2) - q)[:, 1]
    bow = peak * (1.0 - (2.0 * where - 1.0) ** 2)  # closed form at a fraction `where` of the travel
    np.testing.assert_allclose(dy, [0.0, 0.0, peak, bow], atol=1e-9 * (1.0 + abs(peak)) + 1e-12 * (abs(start) + span) ** 2)


def test_straightness_on_a_line_away_from_the_middle_of_the_travel_slopes():
    """The 40 mm line lies at -20 .. 20 mm of a travel -150 .. 50 mm: the deviation follows the travel's bow there
    (its curvature and its slope), not a bow centred on the line."""
    peak, start, span = 8.0, -150.0, 200.0
    effect = Effect("straightness", "x", peak_um=peak, span_mm=span, start_mm=start, error_direction="y")
    dy = 1e3 * _deviation(effect, ("line",))[:, 1]
    x = _nominal(("line",))[:, 0]
    np.testing.assert_allclose(dy, peak * (1.0 - (2.0 * (x - start) / span - 1.0) ** 2), atol=1e-9)
    assert np.polyfit(x, dy, 2)[1] == pytest.approx(-8.0 * peak * (0.0 - (start + span / 2)) / span**2, rel=1e-6)  # slope at x = 0


@pytest.mark.parametrize("tau", [0.0, 1.0])
def test_thermal_drift_leaves_the_circle_open(tau):
    rate = 60.0  # [µm/min] = 1 µm/s
    key = ("circle", "ccw", 40.0)
    reference = _reference(key)
    d = 1e3 * _deviation(Effect("thermal_drift", "x", rate_um_per_min=rate, time_constant_s=tau), key)
    test = np.flatnonzero(reference.measuring)
    t0, t1 = reference.t[test[0]], reference.t[test[-1]]
    drift = (lambda t: t) if tau == 0 else (lambda t: tau * (1 - np.exp(-t / tau)))
    gap = d[test[-1]] - d[test[0]]  # the test circle starts and ends at the same commanded point
    assert gap[0] == pytest.approx(rate / 60 * (drift(t1) - drift(t0)), rel=1e-9)
    assert gap[1] == 0.0


@pytest.mark.parametrize("tau", [0.0, 2.0])
def test_thermal_growth_grows_linearly_with_position_on_a_line_run_twice(tau):
    """The 40 mm line along X, out, back and out again: on both outward passes the drift over its time
    factor (t, or τ·(1 − exp(−t/τ))) is a straight line in x whose slope is the growth in ppm/min."""
    rate, growth, reference_mm = 60.0, 3000.0, -20.0  # [µm/min], [ppm/min] = 50 µm/m per s, the line's start
    one = _reference(("line",)).position
    hold = np.repeat(one[-1:], 200, axis=0)
    path = np.concatenate([np.repeat(one[:1], 200, axis=0), one, hold, one[::-1], np.repeat(one[:1], 200, axis=0), one, hold])
    t = DT * np.arange(len(path))
    run = Trace(t, path, path, ("x", "y"))
    effect = Effect("thermal_drift", "x", rate_um_per_min=rate, growth_ppm_per_min=growth, reference_mm=reference_mm,
                    time_constant_s=tau)
    x = simulate(MACHINE, run).tool_position[:, 0]
    dx = simulate(Model(MACHINE, (effect,)), run).tool_position[:, 0] - x
    drift_time = t if tau == 0 else tau * (1 - np.exp(-t / tau))
    first = 200 + np.arange(len(one))  # the two outward passes
    second = first + 2 * len(one) + 400
    ends = []
    for k in (first, second):
        slope, intercept = np.polyfit(x[k], dx[k] / drift_time[k], 1)  # [mm/s per mm], [mm/s]
        assert np.abs(np.polyval((slope, intercept), x[k]) - dx[k] / drift_time[k]).max() < 1e-9 * abs(intercept)
        assert slope * 60 * 1e6 == pytest.approx(growth, rel=1e-6)
        assert intercept * 60 * 1e3 == pytest.approx(rate - growth * 1e-3 * reference_mm, rel=1e-6)
        ends.append(dx[k[-1]])
    assert ends[1] > ends[0] > 0  # the same position, later: the drift has grown


# -- command and servo effects: a 45° ellipse that flips with direction and grows with feed --


@pytest.mark.parametrize("feed", [20.0, 40.0])
def test_command_delay_is_a_45_degree_ellipse_that_flips_and_grows_with_feed(feed):
    tau = 2e-3
    omega = feed / R
    for direction, sign in (("ccw", -1), ("cw", 1)):
        h = _harmonics(*_polar(Effect("time_delay", "y", delay_s=tau), direction, feed))
        # y(t − τ) = R sin(θ − ωτ): Δr = −Rωτ cos θ sin θ for CCW, + for CW (the loop passes it with |T| ≈ 1)
        assert h["s2"] == pytest.approx(sign * 1e3 * R * omega * tau / 2, rel=0.02)
        assert abs(h["c2"]) < 0.05 * abs(h["s2"])


def test_gain_mismatch_is_a_45_degree_ellipse_that_flips_and_grows_with_feed():
    ratio = 0.8
    sizes = {}
    for feed in (20.0, 40.0):
        for direction, sign in (("ccw", -1), ("cw", 1)):
            h = _harmonics(*_polar(Effect("gain_mismatch", "y", kp_ratio=ratio), direction, feed))
            # first-order position loops: Y lags by ω(1/(ratio·kp) − 1/kp) more than X
            lag = feed / R * (1 / (ratio * AXIS["kp"]) - 1 / AXIS["kp"])
            assert h["s2"] == pytest.approx(sign * 1e3 * R * lag / 2, rel=0.05)
            sizes[feed, direction] = abs(h["s2"])
    assert sizes[40.0, "ccw"] / sizes[20.0, "ccw"] == pytest.approx(2.0, rel=0.05)


def test_feedback_delay_flips_with_direction():
    signs = [np.sign(_harmonics(*_polar(Effect("time_delay", "y", delay_s=2e-3, kind="feedback"), d, 20.0))["s2"])
             for d in ("ccw", "cw")]
    assert signs[0] == -signs[1] != 0


# -- in-loop effects: what happens at the reversals of X (0° and 180°) -----------------------


def _around_reversals(effect, direction, before, after):
    """The radial deviation [µm] and angle (travel direction) at X's two reversals, per window."""
    theta, dr = _polar(effect, direction, 20.0)
    sign = 1 if direction == "ccw" else -1
    out = []
    for reversal in (0.0, np.pi):
        travelled = sign * np.angle(np.exp(1j * (theta - reversal)))  # > 0 after the reversal
        out.append([(dr / np.abs(np.cos(theta)))[(travelled > lo) & (travelled < hi)] for lo, hi in (before, after)])
    return out


@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_backlash_with_motor_feedback_steps_by_the_lost_motion_at_x_reversals(direction):
    lost = 10.0  # [µm]
    windows = _around_reversals(Effect("backlash", "x", lost_motion_um=lost), direction,
                                np.radians((-25, -5)), np.radians((5, 25)))
    for before, after in windows:  # the table lags by half the play either side of the motor
        assert np.median(after) - np.median(before) == pytest.approx(lost, rel=0.02)


def test_friction_spikes_after_reversal_grow_with_the_friction_level():
    peaks = []
    for force in (20.0, 60.0):
        windows = _around_reversals(Effect("coulomb_friction", "x", force_N=force), "ccw",
                                    np.radians((-30, -10)), np.radians((0, 30)))
        for before, after in windows:
            assert np.abs(before).max() < 0.1 * after.max()  # nothing before the reversal ...
        peaks.append(min(after.max() for _, after in windows))  # ... an outward spike just after it
    assert peaks[0] > 1.0  # [µm]
    assert peaks[1] > 2 * peaks[0]


@pytest.mark.parametrize("freq", [60.0, 120.0])
def test_vibration_rings_at_the_mode_frequency_after_an_acceleration(freq):
    zeta, mass_ratio = 0.02, 0.05
    accelerating = np.flatnonzero(_reference(("line",)).acceleration[:, 0] != 0)
    end = accelerating[np.flatnonzero(np.diff(accelerating) > 1)[0]] + 1  # end of the first acceleration
    effect = Effect("vibration", "x", freq_hz=freq, damping_ratio=zeta, mass_ratio=mass_ratio)
    ringing = np.diff(_deviation(effect, ("line",))[end : end + 400, 0], 2)  # 2nd difference: the slow part drops out
    spectrum = np.abs(np.fft.rfft(ringing - ringing.mean(), 16384))
    peak = np.fft.rfftfreq(16384, DT)[np.argmax(spectrum)]
    # between the mode with the carriage held (f·√(1−ζ²)) and with the carriage free (f/√(1 − mass ratio))
    assert freq * np.sqrt(1 - zeta**2) * 0.99 < peak < freq / np.sqrt(1 - mass_ratio) * 1.01


def test_noise_on_the_recorded_position_has_its_rms():
    rms = 0.5  # [µm]
    d = 1e3 * _deviation(Effect("noise", "x", rms_um=rms, seed=3), ("line",))
    assert np.sqrt(np.mean(d[:, 0] ** 2)) == pytest.approx(rms, rel=0.05)
    assert np.all(d[:, 1] == 0)
