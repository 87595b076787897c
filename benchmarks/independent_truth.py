"""Hidden-effect traces from a simulator written apart from contoursim: the independent truth of bench_diagnose.

Nothing here comes from contoursim (not its kernel, effects, paths or
trace writer): the traces are what a drive built from the physics would log,
written in the measured-trace CSV of DESIGN.md, with beside each one the
machine's data sheet as a machine file. Two families:

- ``rigid``: a feed axis whose motor side (30 % of the moving mass) drives
  the table through a screw stiff enough to lock them (relative mode
  1.5–2.5 kHz); Dahl friction where friction is the hidden effect;
  0.25 ms servo; trapezoid or jerk-filtered (one moving average)
  interpolation; logged every 1 ms.
- ``two_mass``: the same chain with a softer screw (relative mode
  250–600 Hz, 2–5 % damped), LuGre friction with a Stribeck hump, position
  feedback from the motor encoder or a linear scale (per machine), S-curve
  interpolation (two moving averages), 0.25 or 0.5 ms servo, logged every
  0.5–2 ms.

Common to both: the plant (states: motor-side and table positions and
velocities, an optional tool-side mass, the friction state, the motor
current behind a first-order current loop of 0.8–1.5 kHz) is integrated
in continuous time by RK4 substeps of at most 2.5 µs; the controller runs
once per servo period: a P position loop (velocity feedforward 0, 0.8
or 1) around a PI velocity loop with anti-windup (conditional
integration at the current limit), the velocity being the backward
difference of the quantised motor encoder (optionally low-passed), with a
computation delay of 0 or 1 period; gains drawn from typical bandwidths,
then lowered where the axis rings (:func:`_commission`, as at commissioning). The logged value of each row is
sampled at the row's time plus a jitter of up to ±2 % of the servo period
(the CSV's ``t`` stays uniform, as the contract requires), seen by an
instrument with white noise (0.05–0.3 µm RMS) and a 0.05 µm resolution.
The data sheet gives the controller exactly (kp, kv, ti, vff, servo
period, and the drive's settings: velocity from encoder differences, its
filter ``y += dt/(τ + dt)·(raw − y)`` as the cut-off
``ln(1 + dt/τ)/(2π·dt)`` of its pole, as contoursim's pole-matched filter
reads it, the computation delay, the current loop's bandwidth as drives
quote it, to 10 Hz), where each axis's position loop reads (the motor
encoder or a scale: for a hidden backlash, the side its effect closes the
loop on), the plant (total mass, force constant, damping) each off by up
to ±3 %, the motor side's mass ``m1`` and the screw's axial stiffness
(``reduced·ω_rel²``, ``reduced = m1·(m2 + m3)/m``) each off by up to ±5 %
(drawn after the others, so that the traces and the other entries stay as
they were), the screw's damping ratio as a data sheet would guess it
(:data:`SHEET_SCREW_DAMPING`, not the truth's 0.02–0.05) and each axis's
travel (0–400 mm, the trace's coordinates); it knows nothing of the
encoder resolution.

The hidden effects, each as physics rather than as contoursim models them:
``backlash`` (a dead zone in the screw coupling, position loop on the motor
encoder or on a scale on the table), ``coulomb_friction`` (the Dahl or
LuGre law, graded by its sliding level Fc), ``gain_mismatch`` (one axis's
kp), ``time_delay`` (the axis's command, or its position feedback, late by
a fraction of periods, interpolated), ``vibration`` (a tool-side mass of
10–30 % on a spring and damper, graded by the frequency with the table held),
and the geometric ones acting on the instrument's reading in machine
coordinates: ``squareness`` (x read as ``x − α·y``: the angle between the
positive axes exceeds 90° for α > 0), ``scale_error``, ``cyclic_error``
(the screw's lead), ``straightness`` (a bow over the axis's whole travel
of 400 mm, not over the test path; graded by its curvature) and
``thermal_drift``. A case may hide several at once (an effect named twice:
on both axes), each acting as it would alone.

Public: :func:`make_case` (one trace and its data sheet into a folder) and
:data:`EFFECTS` (the hidden effects a case may carry).
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

EFFECTS = ("backlash", "coulomb_friction", "gain_mismatch", "squareness", "scale_error", "cyclic_error",
           "straightness", "time_delay", "thermal_drift", "vibration")
FAMILIES = ("rigid", "two_mass")
TRAVEL_MM = 400.0  # each axis's travel in machine coordinates [mm]: 0 .. TRAVEL_MM
_SUBSTEP = 2.5e-6  # longest RK4 substep [s] (the LuGre bristles are stiff: 10 µs diverges)
# The screw's damping ratio a data sheet gives: not the truth's (0.02–0.05, drawn per axis), the top of the typical
# range, because a commissioned axis is stable. _commission leaves the two_mass axes close to the edge (a gain
# margin of 1.0–1.2 at the screw's mode) and a lower guess makes a stable axis's model unstable: with 0.03, 12
# of the 44 two_mass axes of bench_diagnose's seeds 1 and 2 (every other value exact), with 0.04 two, with 0.05 none.
SHEET_SCREW_DAMPING = 0.05

# plant parameter vector (SI): indices into `p`
_M1, _M2, _M3, _K12, _C12, _PLAY, _C, _K3, _C3, _FRICTION, _FC, _FS, _VS, _S0, _S1, _TAU_I, _KF = range(17)


@njit(cache=True)
def _rhs(s, p, i_cmd, out):
    """Time derivative of the plant state ``s = (xm, vm, xt, vt, xo, vo, z, i)`` [m, m/s, friction state, A]."""
    xm, vm, xt, vt, xo, vo, z, i = s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]
    stretch = xm - xt
    half = 0.5 * p[_PLAY]
    if stretch > half:
        f12 = p[_K12] * (stretch - half) + p[_C12] * (vm - vt)
    elif stretch < -half:
        f12 = p[_K12] * (stretch + half) + p[_C12] * (vm - vt)
    else:
        f12 = 0.0
    if p[_M3] > 0.0:
        f3 = p[_K3] * (xt - xo) + p[_C3] * (vt - vo)
    else:
        f3 = 0.0
    friction = 0.0
    dz = 0.0
    if p[_FRICTION] == 1.0:  # Dahl: z is the friction force [N]
        dz = p[_S0] * (vt - abs(vt) * z / p[_FC])
        friction = z
    elif p[_FRICTION] == 2.0:  # LuGre: z is the bristle deflection [m]
        g = p[_FC] + (p[_FS] - p[_FC]) * np.exp(-(vt / p[_VS]) ** 2)
        dz = vt - p[_S0] * abs(vt) * z / g
        friction = p[_S0] * z + p[_S1] * dz
    out[0] = vm
    out[1] = (p[_KF] * i - f12) / p[_M1]
    out[2] = vt
    out[3] = (f12 - f3 - p[_C] * vt - friction) / p[_M2]
    if p[_M3] > 0.0:
        out[4] = vo
        out[5] = f3 / p[_M3]
    else:
        out[4] = vt
        out[5] = out[3]
    out[6] = dz
    out[7] = (i_cmd - i) / p[_TAU_I]


@njit(cache=True)
def _run_axis(xref, vref, p, ctrl, dt, substeps):
    """One axis, controller and plant, over the servo samples of `xref` [m], `vref` [m/s].

    ``ctrl = (kp, kv, ti, vff, i_max, computation delay [periods], velocity filter time constant [s],
    position feedback 0 motor / 1 scale, motor encoder resolution [m], scale resolution [m],
    position-feedback delay [periods], the side the play is closed on at the start: +1 after a move in +, -1, 0
    centred)``. At the start the axis is at rest in position: the loop holds what it reads at the first sample (the
    motor, or the table on a scale) with the screw's stretch at that edge of its dead zone.

    Returns the table and tool positions [m] at the servo instants, shape (N,) each, and the
    tool position half a period later (for jittered logging), shape (N,).
    """
    n = xref.size
    kp, kv, ti, vff, i_max = ctrl[0], ctrl[1], ctrl[2], ctrl[3], ctrl[4]
    comp_delay, tau_v, scale_fb, res_m, res_s, fb_delay = int(ctrl[5]), ctrl[6], ctrl[7], ctrl[8], ctrl[9], ctrl[10]
    half, approach = 0.5 * p[_PLAY], ctrl[11]
    s = np.zeros(8)
    s[0] = xref[0] + (approach * half if scale_fb > 0.5 else 0.0)  # the motor, beyond the table on a scale
    s[2] = s[0] - approach * half  # the table: stretch xm - xt at the edge the approach leaves it
    s[4] = s[2]
    k1, k2, k3, k4, tmp = np.zeros(8), np.zeros(8), np.zeros(8), np.zeros(8), np.zeros(8)
    table, tool, tool_mid, command = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    history = np.zeros(n)
    enc_last = np.round(s[0] / res_m) * res_m
    v_f, integral, held = 0.0, 0.0, 0.0
    h = dt / substeps
    for k in range(n):
        table[k] = s[2]
        tool[k] = s[4]
        enc_m = np.round(s[0] / res_m) * res_m
        history[k] = np.round(s[2] / res_s) * res_s if scale_fb > 0.5 else enc_m
        back = k - fb_delay
        if back <= 0.0:
            position = history[0]
        else:
            j = int(np.floor(back))
            frac = back - j
            position = history[j] if frac == 0.0 else (1.0 - frac) * history[j] + frac * history[j + 1]
        v_raw = (enc_m - enc_last) / dt
        enc_last = enc_m
        v_f = v_raw if tau_v <= 0.0 else v_f + dt / (tau_v + dt) * (v_raw - v_f)
        e_v = kp * (xref[k] - position) + vff * vref[k] - v_f
        trial = integral + (e_v * dt / ti if ti > 0.0 else 0.0)
        current = kv * (e_v + trial)
        if abs(current) <= i_max or (current > 0.0) != (e_v > 0.0):
            integral = trial  # conditional integration: no windup at the current limit
        current = min(max(kv * (e_v + integral), -i_max), i_max)
        command[k] = current
        applied = held if comp_delay == 1 else current
        held = current
        for step in range(substeps):
            _rhs(s, p, applied, k1)
            for m in range(8):
                tmp[m] = s[m] + 0.5 * h * k1[m]
            _rhs(tmp, p, applied, k2)
            for m in range(8):
                tmp[m] = s[m] + 0.5 * h * k2[m]
            _rhs(tmp, p, applied, k3)
            for m in range(8):
                tmp[m] = s[m] + h * k3[m]
            _rhs(tmp, p, applied, k4)
            for m in range(8):
                s[m] += h / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            if step == substeps // 2 - 1:
                tool_mid[k] = s[4]
    return table, tool, tool_mid, command


# -- the reference: paths and an interpolator of their own ---------------------------------------


def _circle(radius, direction):
    theta = np.linspace(0.0, 2 * np.pi, max(2000, int(2 * np.pi * radius / 0.005)))
    return radius * np.column_stack([np.cos(theta) - 1.0, (1 if direction == "ccw" else -1) * np.sin(theta)])


def _trefoil(radius):
    theta = np.linspace(0.0, 2 * np.pi, 60000)
    r = radius * (1.0 + 0.25 * np.cos(3 * theta))
    return np.column_stack([r * np.cos(theta) - r[0], r * np.sin(theta)])


def _rounded_square(side, corner):
    """A square of `side` [mm], corners rounded to `corner`, run CCW from its bottom edge's middle."""
    half = side / 2 - corner
    parts = []
    for k in range(4):
        rot = np.array([[np.cos(k * np.pi / 2), -np.sin(k * np.pi / 2)], [np.sin(k * np.pi / 2), np.cos(k * np.pi / 2)]])
        line = np.column_stack([np.linspace(-half, half, int(2 * half / 0.005)), np.full(int(2 * half / 0.005), -side / 2)])
        if k == 0:
            line = line[line[:, 0] >= 0]
        phi = np.linspace(-np.pi / 2, 0.0, 400)
        arc = np.column_stack([half + corner * np.cos(phi), -half + corner * np.sin(phi)])  # the edge's far corner
        parts += [line @ rot.T, arc @ rot.T]
    first = np.column_stack([np.linspace(-half, 0.0, int(half / 0.005)), np.full(int(half / 0.005), -side / 2)])
    points = np.vstack(parts + [first])
    return points - points[0]


def _profile(length, feed, accel, windows, dt):
    """Path station s(t) [mm] of a trapezoid velocity profile smoothed by moving averages of `windows` [s]."""
    feed = min(feed, np.sqrt(length * accel))
    t_acc, t_run = feed / accel, length / feed - feed / accel
    t = np.arange(int(np.ceil((2 * t_acc + t_run) / dt)) + 1) * dt
    v = np.minimum.reduce([accel * t, np.full(t.size, feed), accel * (2 * t_acc + t_run - t)]).clip(0.0)
    for window in windows:
        w = max(1, int(round(window / dt)))
        v = np.convolve(np.concatenate([v, np.zeros(w)]), np.ones(w) / w)[: v.size + w]
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt])
    return s * (length / s[-1])


def _reference(points, feed, accel, windows, dt, dwell=(0.1, 0.3)):
    """Positions [mm] and velocities [mm/s] at the servo samples of `points` (a dense polyline) run at `feed`."""
    station = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    s = _profile(station[-1], feed, accel, windows, dt)
    s = np.concatenate([np.zeros(int(dwell[0] / dt)), s, np.full(int(dwell[1] / dt), station[-1])])
    position = np.column_stack([np.interp(s, station, points[:, i]) for i in range(points.shape[1])])
    return position, np.gradient(position, dt, axis=0)


# -- one case ------------------------------------------------------------------------------------


@dataclass
class Case:
    """One generated trace: where it was written and what is hidden in it.

    ``truths`` holds the hidden effects, each ``{"name", "axis", "parameters", "options"}`` in
    contoursim's names and units (empty: none); ``signal_um`` is the RMS they add to the logged
    positions (the same truth run with and without them, noise-free), its mean per axis (a
    constant shift, the instrument's zero) left out [µm].
    """

    family: str
    path: str
    csv: Path
    machine_file: Path
    truths: tuple
    signal_um: float
    duration_s: float
    notes: dict = field(default_factory=dict)


def _axis_machine(rng, family, kp):
    """The true axis (plant and controller) and its data-sheet entries."""
    mass = rng.uniform(100.0, 500.0)
    kf = rng.uniform(400.0, 1500.0)
    omega_v = 2 * np.pi * rng.uniform(25.0, 50.0)  # velocity-loop crossover [rad/s]
    true = dict(mass=mass, kf=kf, damping=rng.uniform(1.0, 3.0) * mass, kv=omega_v * mass / kf,
                ti=rng.uniform(4.0, 8.0) / omega_v, kp=kp, motor_share=rng.uniform(0.2, 0.4),
                tau_i=1.0 / (2 * np.pi * rng.uniform(800.0, 1500.0)), tau_v=rng.choice([0.0, rng.uniform(1e-4, 4e-4)]),
                res_m=0.01 / 2**20, res_s=5e-8)
    relative = rng.uniform(1500.0, 2500.0) if family == "rigid" else rng.uniform(250.0, 600.0)  # screw mode [Hz]
    true["screw_hz"] = relative
    true["screw_zeta"] = 0.02 if family == "rigid" else rng.uniform(0.02, 0.05)
    return true


def _commission(axis, family, period):
    """Tune the velocity loop down as a drive engineer would until a 10 µm position step settles quietly.

    The drawn gains ignore the screw's compliance, the current loop and the delays; where they
    make the axis ring (a limit cycle at the screw mode), kv is lowered by 20 % (ti raised by
    25 %) until the step response stays within 0.2 µm of its target over its last 0.3 s of 1.5 s,
    no further from it than over 0.3–0.6 s: a loop that is unstable with a slow growth rate can
    look settled at 0.6 s (one grew from 0.19 µm at 0.55 s to 45 µm at 1.2 s).
    """
    t = np.arange(int(1.5 / period)) * period
    step = np.full(t.size, 1e-5)
    step[0] = 0.0
    for _ in range(12):
        ctrl = np.array([axis["kp"], axis["kv"], axis["ti"], axis["vff"], 50.0, axis["computation_delay"], axis["tau_v"],
                         float(axis["scale_feedback"]), axis["res_m"], axis["res_s"], 0.0, 0.0])
        table, tool, _, _ = _run_axis(step, np.zeros(t.size), _plant_vector(axis, (), family, ""), ctrl, period,
                                   int(np.ceil(period / _SUBSTEP)))
        tail = np.max(np.abs(tool[t > t[-1] - 0.3] - 1e-5))
        earlier = np.max(np.abs(tool[(t >= 0.3) & (t < 0.6)] - 1e-5))
        if np.all(np.isfinite(tool)) and tail < 2e-7 and tail <= max(earlier, 1e-8):
            return
        axis["kv"] *= 0.8
        axis["ti"] *= 1.25
    raise RuntimeError("the axis could not be tuned to a quiet step response")


def _plant_vector(axis, effects, family, axis_name):
    """The parameter vector of :func:`_rhs` for one true axis and the hidden `effects`."""
    mine = [e for e in effects if e["axis"] == axis_name]
    m = axis["mass"]
    m3 = 0.0
    vib = next((e for e in mine if e["name"] == "vibration"), None)
    if vib is not None:
        m3 = vib["notes"]["tool_share"] * m
    m1 = axis["motor_share"] * m
    m2 = m - m1 - m3
    reduced = m1 * (m2 + m3) / m
    omega = 2 * np.pi * axis["screw_hz"]
    p = np.zeros(17)
    p[_M1], p[_M2], p[_M3] = m1, m2, m3
    p[_K12] = reduced * omega**2
    p[_C12] = 2 * axis["screw_zeta"] * reduced * omega
    p[_C] = axis["damping"]
    p[_TAU_I], p[_KF] = axis["tau_i"], axis["kf"]
    p[_FC] = p[_FS] = p[_VS] = 1.0
    if vib is not None:
        w3 = 2 * np.pi * vib["parameters"]["freq_hz"]
        p[_K3] = m3 * w3**2
        p[_C3] = 2 * vib["parameters"]["damping_ratio"] * m3 * w3
    for effect in mine:
        if effect["name"] == "backlash":
            p[_PLAY] = effect["parameters"]["lost_motion_um"] * 1e-6
        if effect["name"] == "coulomb_friction":
            fc = effect["parameters"]["force_N"]
            p[_FC] = fc
            presliding = effect["notes"]["presliding_m"]
            if family == "rigid":
                p[_FRICTION], p[_S0] = 1.0, fc / presliding
            else:
                p[_FRICTION], p[_S0] = 2.0, fc / presliding
                p[_FS], p[_VS] = effect["notes"]["stribeck"] * fc, effect["notes"]["stribeck_velocity"]
                p[_S1] = 0.2 * np.sqrt(p[_S0] * m2)
    return p


def _hidden(rng, name, axes, period):
    """A hidden effect of random size within its typical range on a random axis, in contoursim's names and units."""
    sign = float(rng.choice([-1.0, 1.0]))
    axis = str(rng.choice(axes))
    effect = dict(name=name, axis=axis, parameters={}, options={}, notes={})
    prm = effect["parameters"]
    if name == "backlash":
        prm["lost_motion_um"] = rng.uniform(2, 20)
        effect["options"]["feedback"] = str(rng.choice(["motor", "scale"]))
    elif name == "coulomb_friction":
        prm["force_N"] = float(np.exp(rng.uniform(np.log(5), np.log(200))))
        effect["notes"].update(presliding_m=rng.uniform(1e-6, 3e-6), stribeck=rng.uniform(1.1, 1.5),
                               stribeck_velocity=rng.uniform(1e-3, 5e-3))
    elif name == "gain_mismatch":
        prm["kp_ratio"] = rng.uniform(0.7, 1.3)
    elif name == "squareness":
        effect["axis"] = "xy"
        prm["angle_urad"] = sign * rng.uniform(20, 200)
    elif name == "scale_error":
        prm["ppm"] = sign * rng.uniform(10, 100)
    elif name == "cyclic_error":
        prm.update(amplitude_um=rng.uniform(1, 5), period_mm=float(rng.choice([5.0, 10.0, 16.0, 20.0])),
                   phase_deg=rng.uniform(0, 360))
    elif name == "straightness":
        prm.update(peak_um=sign * rng.uniform(2, 15), span_mm=TRAVEL_MM)
        effect["options"]["error_direction"] = "y" if axis == "x" else "x"
    elif name == "time_delay":
        kind = str(rng.choice(["command", "feedback"]))
        prm["delay_s"] = rng.uniform(1e-4, 3e-3) if kind == "command" else rng.uniform(0.5, 4.0) * period
        effect["options"]["kind"] = kind
    elif name == "thermal_drift":
        prm["rate_um_per_min"] = sign * rng.uniform(1, 10)
    elif name == "vibration":
        prm.update(freq_hz=rng.uniform(30, 150), damping_ratio=rng.uniform(0.01, 0.2))
        effect["notes"]["tool_share"] = rng.uniform(0.1, 0.3)
    else:
        raise ValueError(f"unknown effect {name!r}")
    return effect


def _geometry(q, t, effects):
    """The instrument's reading [mm] of machine positions `q` (N, 2) [mm] at times `t` [s] with the geometric ones of
    `effects`."""
    q = q.copy()
    for effect in effects:
        q = _geometric(q, t, effect)
    return q


def _geometric(q, t, effect):
    """`q` [mm] read with one effect (in place; unchanged by an effect that is not geometric)."""
    name, prm = effect["name"], effect["parameters"]
    i = "xy".index(effect["axis"][0])
    if name == "squareness":
        q[:, 0] = q[:, 0] - prm["angle_urad"] * 1e-6 * q[:, 1]
    elif name == "scale_error":
        q[:, i] = q[:, i] * (1.0 + prm["ppm"] * 1e-6)
    elif name == "cyclic_error":
        q[:, i] += prm["amplitude_um"] * 1e-3 * np.sin(2 * np.pi * q[:, i] / prm["period_mm"] + np.radians(prm["phase_deg"]))
    elif name == "straightness":
        j = "xy".index(effect["options"]["error_direction"])
        u = 2.0 * (q[:, i] - TRAVEL_MM / 2) / TRAVEL_MM
        q[:, j] += prm["peak_um"] * 1e-3 * (1.0 - u**2)
    elif name == "thermal_drift":
        q[:, i] += prm["rate_um_per_min"] * 1e-3 * t / 60.0
    return q


def _simulate(axes, machine, reference, velocity, effects, family, period, every, jitter):
    """Noise-free logged tool positions [mm] (rows every `every` servo samples, sampled late by `jitter` [periods]),
    and the drives' current commands at those servo samples [A], each shape (rows, axes)."""
    columns, currents = [], []
    for i, a in enumerate(axes):
        axis = machine[a]
        x, v = reference[:, i] * 1e-3, velocity[:, i] * 1e-3
        kp, fb_delay, scale, approach = axis["kp"], 0.0, axis["scale_feedback"], 0.0
        for effect in (e for e in effects if e["axis"] == a):
            prm = effect["parameters"]
            if effect["name"] == "gain_mismatch":
                kp *= prm["kp_ratio"]
            if effect["name"] == "time_delay" and effect["options"]["kind"] == "command":
                t = np.arange(x.size) * period
                x, v = np.interp(t - prm["delay_s"], t, x), np.interp(t - prm["delay_s"], t, v)
            if effect["name"] == "time_delay" and effect["options"]["kind"] == "feedback":
                fb_delay = prm["delay_s"] / period
            if effect["name"] == "backlash":
                scale = effect["options"]["feedback"] == "scale"
                approach = {"+": 1.0, "-": -1.0}.get(effect["options"].get("approach"), 0.0)
        ctrl = np.array([kp, axis["kv"], axis["ti"], axis["vff"], 50.0, axis["computation_delay"], axis["tau_v"],
                         float(scale), axis["res_m"], axis["res_s"], fb_delay, approach])
        substeps = int(np.ceil(period / _SUBSTEP))
        _, tool, mid, command = _run_axis(x, v, _plant_vector(axis, effects, family, a), ctrl, period, substeps)
        rows = np.arange(0, x.size, every)
        currents.append(command[rows])
        late = np.clip(jitter, 0.0, 0.5)  # sampled late by a fraction of the period: between the instant and mid-period
        early = np.clip(-jitter, 0.0, 0.5)
        value = tool[rows] + 2 * late * (mid[rows] - tool[rows])
        before = np.concatenate([[tool[0]], mid[:-1]])[rows]  # half a period earlier
        value = value + 2 * early * (before - tool[rows])
        columns.append(1e3 * value)
    return np.column_stack(columns), np.column_stack(currents)


def make_case(family, effects, seed, folder, path=None, currents=False, approach=None, laps=1):
    """Generate one trace of `family` with the hidden `effects` into `folder`.

    Parameters
    ----------
    family : {"rigid", "two_mass"}
    effects : str, sequence of str or None
        Of :data:`EFFECTS`, one or several (``None`` or empty: none); an effect named twice acts on both axes
        (a squareness, which has one pair of axes, cannot be).
    seed : int
    folder : Path
        Receives ``case_<seed>.csv`` and ``case_<seed>.toml`` (the data sheet).
    path : str, optional
        ``"circle_ccw"``, ``"circle_cw"``, ``"trefoil"``, ``"square"`` (default: drawn from these), or
        ``"circle_both"`` (never drawn): the circle run CCW, then after a stop CW, as a ballbar test does.
    currents : bool
        Also log each axis's current command as the drive computed it at the logged servo samples
        (``<axis>_current`` [A]); the positions and the data sheet are the same either way.
    approach : {"+", "-"}, optional
        A hidden backlash's play closed at the start as a move that way leaves it, the axis at rest in position
        (its truth's option ``approach``); default: centred, the stretch zero.
    laps : int
        The closed path run this many times in one move, each lap at the feed of the first (a trace about as
        many times as long of the same machine and effects, its noise level drawn anew: how the time a diagnosis
        takes grows with a trace's length); ``circle_both`` runs each way this many times.

    Returns
    -------
    Case
    """
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    if approach not in (None, "+", "-"):
        raise ValueError(f'approach must be "+", "-" or None (the play centred), got {approach!r}')
    if isinstance(laps, bool) or not isinstance(laps, (int, np.integer)) or laps < 1:
        raise ValueError(f"laps must be a whole number of 1 or more, got {laps!r}")
    rng = np.random.default_rng(seed)
    axes = ("x", "y")
    period = 2.5e-4 if family == "rigid" else float(rng.choice([2.5e-4, 5e-4]))
    log = 1e-3 if family == "rigid" else float(rng.choice([5e-4, 1e-3, 2e-3]))
    every = max(1, int(round(log / period)))
    kp = rng.uniform(25.0, 45.0)
    vff = float(rng.choice([0.0, 0.8, 1.0]))
    computation_delay = int(rng.integers(0, 2))
    scale_feedback = family == "two_mass" and bool(rng.integers(0, 2))
    machine = {}
    for a in axes:
        machine[a] = _axis_machine(rng, family, kp)
        machine[a].update(vff=vff, computation_delay=computation_delay, scale_feedback=scale_feedback)
        _commission(machine[a], family, period)
    path = path or str(rng.choice(["circle_ccw", "circle_cw", "trefoil", "square"]))
    size = rng.uniform(10.0, 60.0)
    points = {"circle_ccw": lambda: _circle(size, "ccw"), "circle_cw": lambda: _circle(size, "cw"),
              "circle_both": lambda: _circle(size, "ccw"),
              "trefoil": lambda: _trefoil(size), "square": lambda: _rounded_square(2 * size, rng.uniform(1.0, 5.0))}[path]()
    start = rng.uniform(TRAVEL_MM * 0.3, TRAVEL_MM * 0.7, 2) + np.array([size, 0.0])
    station = np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))
    feed = max(rng.uniform(1000.0, 6000.0) / 60.0, station / 8.0)  # at most about 8 s of motion a lap [mm/s]
    accel = rng.uniform(500.0, 3000.0)
    windows = (() if rng.integers(0, 2) else (rng.uniform(4e-3, 1.5e-2),)) if family == "rigid" else \
        (rng.uniform(4e-3, 1.5e-2), rng.uniform(2e-3, 8e-3))
    runs = [points, _circle(size, "cw")] if path == "circle_both" else [points]  # a ballbar's two runs, a stop between
    runs = [np.vstack([p] + [p[1:]] * (laps - 1)) for p in runs]  # each closed: a lap ends where the next starts
    reference, velocity = (np.vstack(x) for x in zip(*[_reference(p + start, feed, accel, windows, period) for p in runs]))
    hidden = []
    for name in (() if effects is None else (effects,) if isinstance(effects, str) else effects):
        hidden.append(_hidden(rng, name, axes, period))
        if any((e["name"], e["axis"]) == (name, hidden[-1]["axis"]) for e in hidden[:-1]):  # the other axis
            if name == "squareness":
                raise ValueError("a squareness acts on the one pair of axes x, y: it cannot be hidden twice")
            hidden[-1]["axis"] = next(a for a in axes if a != hidden[-1]["axis"])
            if name == "straightness":
                hidden[-1]["options"]["error_direction"] = next(a for a in axes if a != hidden[-1]["axis"])
        if name == "backlash" and approach is not None:
            hidden[-1]["options"]["approach"] = approach
    t = np.arange(reference.shape[0]) * period
    rows = np.arange(0, t.size, every)
    jitter = rng.uniform(-0.02, 0.02, rows.size)
    noise_um = rng.uniform(0.05, 0.3)
    measured, commands = {}, {}  # the logged positions [mm] and current commands [A] of the runs with, without it
    for name, acting in (("with", hidden), ("without", [])):
        if name == "without" and not hidden:
            measured[name] = measured["with"]
            continue
        tool, commands[name] = _simulate(axes, machine, reference, velocity, acting, family, period, every, jitter)
        measured[name] = _geometry(tool, t[rows], acting)
    added = measured["with"] - measured["without"]
    added -= added.mean(axis=0)  # a constant shift is the instrument's zero: no trace shows it
    signal = 1e3 * float(np.sqrt(np.mean(np.sum(added**2, axis=1))))
    actual = measured["with"] + rng.normal(0.0, noise_um * 1e-3, measured["with"].shape)
    actual = np.round(actual / 5e-5) * 5e-5
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    csv, toml = folder / f"case_{seed}.csv", folder / f"case_{seed}.toml"
    _write_csv(csv, t[rows], reference[rows], actual, axes, f"independent truth, family {family}, path {path}, seed {seed}",
               commands["with"] if currents else None)
    _write_data_sheet(toml, machine, period, rng, f"independent truth {family} seed {seed} (data sheet)", hidden)
    truths = tuple({k: e[k] for k in ("name", "axis", "parameters", "options")} for e in hidden)
    notes = dict(period_s=period, log_s=every * period, noise_um=noise_um, vff=vff, computation_delay=computation_delay,
                 scale_feedback=scale_feedback, windows_s=windows,
                 velocity_gain_N_s_per_m={a: machine[a]["kf"] * machine[a]["kv"] for a in axes})
    return Case(family, path, csv, toml, truths, signal, float(t[rows][-1]), notes)


def _write_csv(file, t, reference, actual, axes, comment, current=None):
    """The measured-trace CSV of DESIGN.md: ``t, <axis>_ref, <axis>`` [s, mm], then ``<axis>_current`` [A] with
    `current`."""
    header = ",".join(["t"] + [c for a in axes for c in (f"{a}_ref", a)] + ([] if current is None else
                                                                          [f"{a}_current" for a in axes]))
    table = np.column_stack([t] + [c for i in range(len(axes)) for c in (reference[:, i], actual[:, i])]
                            + ([] if current is None else list(current.T)))
    with open(file, "w", encoding="utf-8") as f:
        f.write(f"# {comment}\n{header}\n")
        for row in table:
            f.write(f"{row[0]:.9f}," + ",".join(f"{v:.6f}" for v in row[1:]) + "\n")


def _write_data_sheet(file, machine, period, rng, name, effects):
    """The machine as its data sheet gives it: controller and drive settings exact (the current loop's bandwidth to
    10 Hz), where the position loop reads (as a backlash of `effects` closes it), total mass, force constant and
    damping within ±3 %, the motor side's mass and the screw's stiffness within ±5 % (drawn after the others), a
    typical screw damping ratio, each axis's travel."""
    off = lambda: rng.uniform(0.97, 1.03)  # noqa: E731
    lines = [f'name = "{name}"', f"servo_period_ms = {1e3 * period:.6g}", ""]
    tables = {}
    for a, axis in machine.items():
        tables[a] = [f"[axes.{a}]", f"mass_kg = {axis['mass'] * off():.6g}", f"force_constant_N_per_A = {axis['kf'] * off():.6g}",
                     f"kv_A_s_per_m = {axis['kv']:.10g}", f"ti_s = {axis['ti']:.10g}", f"kp_per_s = {axis['kp']:.10g}",
                     f"damping_N_s_per_m = {axis['damping'] * off():.6g}", f"vff = {axis['vff']:.6g}",
                     'velocity_feedback = "difference"', f"computation_delay_periods = {axis['computation_delay']}",
                     f"current_bandwidth_hz = {round(1.0 / (2 * np.pi * axis['tau_i']), -1):g}",
                     f"travel_mm = [0, {TRAVEL_MM:g}]"]
        if axis["tau_v"] > 0:  # the drive's filter, y += dt/(τ + dt)·(raw - y), as the cut-off of its pole τ/(τ + dt)
            tables[a].append(f"velocity_filter_hz = {np.log1p(period / axis['tau_v']) / (2 * np.pi * period):.10g}")
    for a, axis in machine.items():  # the screw, drawn after the entries above (which stay as they were)
        scale = axis["scale_feedback"]
        for effect in (e for e in effects if e["name"] == "backlash" and e["axis"] == a):
            scale = effect["options"]["feedback"] == "scale"  # the loop _simulate closes for this case
        m1 = axis["motor_share"] * axis["mass"]
        stiffness = m1 * (axis["mass"] - m1) / axis["mass"] * (2 * np.pi * axis["screw_hz"]) ** 2  # [N/m]
        tables[a] += [f'position_feedback = "{"scale" if scale else "motor"}"',
                      f"motor_mass_kg = {m1 * rng.uniform(0.95, 1.05):.6g}",
                      f"screw_stiffness_N_per_um = {1e-6 * stiffness * rng.uniform(0.95, 1.05):.6g}",
                      f"screw_damping_ratio = {SHEET_SCREW_DAMPING:g}", ""]
    lines += [line for table in tables.values() for line in table]
    Path(file).write_text("\n".join(lines), encoding="utf-8")
