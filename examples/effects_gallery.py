"""A ballbar-style gallery of the effects catalogue: one polar plot per effect, CW and CCW overlaid.

Each effect, at a typical size, is switched on alone on the demo mill, which
runs the ISO 230-4 circle (R = 25 mm, F = 1000 mm/min) both ways. What is
drawn is the radial deviation the effect adds to the nominal machine's run,
over the test circle, against the angle of the tool — the shape a ballbar
technician reads: steps and spikes at the X reversals (0°, 180°), 45°
ellipses that flip with the direction (servo) or do not (geometry), an
axis-aligned ellipse, a ripple, a circle that does not close, and hardly
anything from a structural mode, which the slow circle's small acceleration
(11 mm/s²) barely excites. All plots share one radial scale. Each direction's eleven runs (the nominal one and
one per effect) are one call of ``simulate_batch``.

python examples/effects_gallery.py [OUT_DIR]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from contoursim import paths
from contoursim.effects import Effect
from contoursim.feed import plan, sample
from contoursim.machine import load_machine
from contoursim.model import Model
from contoursim.output import output_dir
from contoursim.simulation import simulate_batch

RADIUS, FEED = 25.0, 1000.0 / 60  # [mm], [mm/s]
EFFECTS = (
    Effect("backlash", "x", lost_motion_um=8.0),
    Effect("coulomb_friction", "x", force_N=60.0),
    Effect("gain_mismatch", "y", kp_ratio=0.97),
    Effect("time_delay", "y", delay_s=1e-3),
    Effect("squareness", "xy", angle_urad=150.0),
    Effect("scale_error", "x", ppm=100.0),
    Effect("cyclic_error", "x", amplitude_um=2.0, period_mm=10.0),
    # a guideway as long as the circle is wide, to show the bow's shape (on a real travel it is mostly a slope)
    Effect("straightness", "x", peak_um=8.0, span_mm=2 * RADIUS, start_mm=-RADIUS, error_direction="y"),
    Effect("thermal_drift", "x", rate_um_per_min=10.0),
    Effect("vibration", "y", freq_hz=40.0, damping_ratio=0.05, mass_ratio=0.3),
)
OFFSET = 10.0  # [µm] zero deviation is drawn at this radius of each polar plot


def radial_deviations(machine, direction):
    """Angle of the tool [rad] and the radial deviation each effect adds [µm], over the test circle."""
    path = paths.iso230_4_circle(RADIUS, direction=direction, start_angle=np.pi / 4)
    reference = sample(path, plan(path, feed=FEED, accel=1000.0, jerk=5e4), machine.servo_period)
    models = [Model(machine)] + [Model(machine, (effect,)) for effect in EFFECTS]
    tool = simulate_batch(models, reference, settle=0.0)["tool_position"][:, reference.measuring]
    radius = np.hypot(tool[..., 0], tool[..., 1])
    theta = np.arctan2(tool[1:, :, 1], tool[1:, :, 0])
    return theta, 1e3 * (radius[1:] - radius[0])


def main(out=Path("contoursim-out")):
    machine = load_machine("demo_mill")
    runs = {direction: radial_deviations(machine, direction) for direction in ("ccw", "cw")}
    limit = max(np.abs(dr).max() for _, dr in runs.values())
    fig, axes = plt.subplots(2, 5, figsize=(15, 6.8), subplot_kw={"projection": "polar"})
    for i, (effect, ax) in enumerate(zip(EFFECTS, axes.flat)):
        for direction, color in (("ccw", "tab:blue"), ("cw", "tab:red")):
            theta, dr = runs[direction]
            ax.plot(theta[i], OFFSET + dr[i], color=color, lw=1.0, label=direction.upper())
        ax.plot(np.linspace(0, 2 * np.pi, 200), np.full(200, OFFSET), "k--", lw=0.6)
        ax.set_rlim(0, OFFSET + limit)
        ticks = np.array([-OFFSET / 2, 0.0, OFFSET / 2])
        ax.set_rticks(OFFSET + ticks, labels=[f"{t:+g}" if t else "0" for t in ticks], fontsize=7)
        ax.set_xticks(np.radians([0, 90, 180, 270]), labels=["0°", "90°", "180°", "270°"], fontsize=7)
        size = effect.parameters[0]
        ax.set_title(f"{effect.name} ({effect.axis})\n{size.name} = {size.value:g}", fontsize=9)
        print(f"{effect.label:<20} radial deviation CCW {np.ptp(runs['ccw'][1][i]):6.2f} µm p-p, "
              f"CW {np.ptp(runs['cw'][1][i]):6.2f} µm p-p")
    axes.flat[0].legend(loc="lower left", bbox_to_anchor=(-0.35, -0.15), fontsize=8)
    fig.suptitle(f"Radial deviation each effect adds on the ISO 230-4 circle (R = {RADIUS:g} mm, "
                 f"F = {60 * FEED:g} mm/min) [µm]; dashed: none; one scale for all", fontsize=11)
    fig.tight_layout()
    file = output_dir(out).file("effects_gallery.png")
    fig.savefig(file, dpi=110)
    plt.close(fig)
    print("wrote", file)
    return runs


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("contoursim-out"))
