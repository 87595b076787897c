"""Generate the nightly circle tests of this folder: a machine whose X backlash grows week by week.

Each trace is an ISO 230-4 circle (trajectories/iso230_4_circle_ccw.toml at
3000 mm/min) on the machine of ``nightly_mill.toml`` with its servo
parameters a little off (±3 %, a new draw each night), a motor-side backlash
on X of 4, 6, 8 and 10 µm on four nights a week apart, 0.1 µm RMS noise,
logged every 2 ms (:func:`contoursim.diagnosis.synthetic_trace`). A fifth
night's log stopped mid-row: the fleet diagnosis reports it as failed.

Run:  python examples/fleet/make_nightly.py [FOLDER]   (default: this folder)
"""

import sys
from dataclasses import replace
from pathlib import Path

from contoursim.diagnosis import synthetic_trace
from contoursim.effects import Effect
from contoursim.machine import load_machine
from contoursim.feed import sample
from contoursim.model import Model
from contoursim.pathfile import library_file, load_path_file
from contoursim.traces import write_trace

HERE = Path(__file__).resolve().parent
NIGHTS = {"2026-10-05": 4.0, "2026-10-12": 6.0, "2026-10-19": 8.0, "2026-10-26": 10.0}  # date -> X backlash [µm]


def write_nights(folder, nights=NIGHTS):
    """Write one trace ``night_<date>.csv`` per night into `folder`, the X backlash [µm] of `nights` (date -> µm) hidden in it."""
    folder = Path(folder)
    machine = load_machine(HERE / "nightly_mill.toml")
    path, settings = load_path_file(library_file("iso230_4_circle_ccw"))
    settings = replace(settings, feed=3000.0 / 60.0)  # [mm/s]
    trajectory = sample(path, settings.plan(path, max_feed=machine.max_feed), machine.servo_period).held(0.1)
    for night, (date, backlash) in enumerate(nights.items()):
        truth = Model(machine, (Effect("backlash", "x", lost_motion_um=backlash),))
        trace = synthetic_trace(truth, trajectory, every=4, seed=night)
        trace = replace(trace, metadata={"date": date, "test": "ISO 230-4 circle, 3000 mm/min"})
        write_trace(folder / f"night_{date}.csv", trace, overwrite=True)
    return [folder / f"night_{date}.csv" for date in nights]


def main(folder=HERE):
    written = write_nights(folder)
    good = written[-1].read_text(encoding="utf-8").splitlines()
    (Path(folder) / "night_2026-11-02.csv").write_text("\n".join(good[:200]) + "\n" + good[200][: len(good[200]) // 2]
                                                     + "\n", encoding="utf-8")  # the logger stopped mid-row
    print(f"{len(written) + 1} nightly traces written to {folder}")


if __name__ == "__main__":
    main(*sys.argv[1:])
