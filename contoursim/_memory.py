"""Memory a command will hold, checked before it starts: a run too large for the machine is refused in one line.

A run's samples are the unit: :data:`RUN_BYTES_PER_SAMPLE` covers one run
from its reference to its trace CSV and plots, :data:`COMPARED_RUN_BYTES_PER_SAMPLE`
each further run a comparison keeps beside it, :data:`DIAGNOSIS_BYTES_PER_SAMPLE`
a diagnosis. A sweep's are its variants (:data:`SWEEP_BYTES_PER_VALUE`); a local cluster's, its worker processes
(:data:`WORKER_BYTES`).
"""

import os

#: Peak memory a simulated sample takes in a run, from the reference to the trace CSV and the plots [bytes].
#: A 1 M-step run of a 2-D circle on the demo machine grows by ~360 bytes a step beyond what a short
#: run takes (benchmarks/bench_user.py); tests/test_feed.py checks the figure covers 2-D and 3-D runs.
RUN_BYTES_PER_SAMPLE = 450

#: Memory each strategy's run adds to a comparison, per sample [bytes]: ``contoursim compare`` on a
#: 79,000-sample circle of the demo mill peaked at 646 bytes a sample with one strategy and 1,479 with
#: six, with its plots (tracemalloc), 167 bytes a further run; tests/test_cli.py checks the figure covers it.
COMPARED_RUN_BYTES_PER_SAMPLE = 250

#: Peak memory of ``diagnose`` per sample of the trace resampled at the servo period [bytes]: a diagnosis of a
#: 2-D circle on the demo mill with backlash and noise, nominal model given, peaked at 3,739 bytes a sample on
#: 78,551 samples and 3,932 on 224,404 (tracemalloc), 4,036 bytes per further sample.
DIAGNOSIS_BYTES_PER_SAMPLE = 4500

#: Peak memory of a sweep per variant and varied parameter, from the drawn values to the table, its CSV and the
#: plots [bytes] (the variants' traces are never held: each batch keeps its figures only). Grid and Latin-hypercube
#: sweeps of demo_mill with 1 to 3 parameters grew by 388-390 (1), 1,174-1,188 (2: the map of both) and 929-944 (3)
#: bytes a variant from 20,000 to 80,000 variants (tracemalloc), at most 587 a variant and parameter.
SWEEP_BYTES_PER_VALUE = 700

#: Memory a worker process of ``--scheduler local:N`` takes [bytes]: contoursim, numba and a sweep's job loaded, a
#: worker of local:2 held 330-334 MB (resident) after 4,000 variants of a demo_mill sweep.
WORKER_BYTES = 400_000_000


def available():
    """Memory the system can give a run now [bytes]: ``MemAvailable`` of /proc/meminfo, else the physical memory.

    Returns
    -------
    int or None
        ``None`` where neither is known.
    """
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return 1024 * int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def check(samples, what, advice, runs=1, per_sample=RUN_BYTES_PER_SAMPLE):
    """Refuse runs of `samples` samples that would not fit in the memory available.

    Parameters
    ----------
    samples : int
        Samples of each run.
    what : str
        What the samples are, starting the message (e.g. ``"the motion lasts 10 s: at dt = 0.001 s"``).
    advice : str
        What to check, ending the message.
    runs : int
        Runs held at once: the first takes `per_sample` bytes a sample,
        each further one :data:`COMPARED_RUN_BYTES_PER_SAMPLE`.
    per_sample : int
        Bytes a sample of the first run takes: :data:`RUN_BYTES_PER_SAMPLE`
        for a simulation, :data:`DIAGNOSIS_BYTES_PER_SAMPLE` for a diagnosis.

    Raises
    ------
    ValueError
        More memory is needed than is available (nothing is checked where that is unknown).
    """
    samples = float(samples)  # a Python int of 1e300 samples would not convert in the message
    held = "a run of them" if runs == 1 else f"{runs} runs of them"
    _fits(samples * (per_sample + (runs - 1) * COMPARED_RUN_BYTES_PER_SAMPLE),
          f"{what} that is {samples:.4g} samples, {held} needs", advice)


def check_diagnosis(trace, model, source):
    """Refuse the diagnosis of `trace` that would not fit in the memory available: every servo period it lasts is
    simulated, :data:`DIAGNOSIS_BYTES_PER_SAMPLE` each.

    Parameters
    ----------
    trace : contoursim.traces.Trace
    model : contoursim.model.Model or None
        The nominal model, whose servo period the trace is resampled at; ``None``: identified from the trace
        (:func:`contoursim.identify.servo_period_for`).
    source : str
        The trace's file, starting the message.

    Raises
    ------
    ValueError
        More memory is needed than is available (nothing is checked where that is unknown).
    """
    from .identify import servo_period_for

    period = model.machine.servo_period if model is not None else servo_period_for(trace.dt)
    duration = trace.t[-1] - trace.t[0]
    check(int(duration / period) + 1, f"{source}: the trace lasts {duration:.6g} s: every servo period of {period:.6g} s",
          "check the unit of the trace's time column (e.g. a line '# units: t [ms]') and the servo period",
          per_sample=DIAGNOSIS_BYTES_PER_SAMPLE)


def check_sweep(variants, parameters, what, advice):
    """Refuse a sweep of `variants` variants of `parameters` parameters that would not fit in the memory available.

    Parameters
    ----------
    variants : int
    parameters : int
    what : str
        What the variants are, starting the message (e.g. ``"vary.count: a grid of 10000 x 10000 points"``).
    advice : str
        What to change, ending the message.

    Raises
    ------
    ValueError
        More memory is needed than is available (nothing is checked where that is unknown).
    """
    variants = float(variants)
    _fits(variants * parameters * SWEEP_BYTES_PER_VALUE, f"{what}, {variants:.4g} variants, needs", advice)


def check_workers(workers):
    """Refuse a local cluster of `workers` worker processes (:data:`WORKER_BYTES` each) that would not fit in memory.

    Parameters
    ----------
    workers : int

    Raises
    ------
    ValueError
        More memory is needed than is available (nothing is checked where that is unknown).
    """
    _fits(workers * WORKER_BYTES, f"--scheduler local:{workers}: {workers} worker processes need",
          f"start fewer (this machine has {os.cpu_count() or 'an unknown number of'} cores; more workers than cores "
          "run no faster)")


def _fits(needed, what, advice):
    """Raise ValueError ``"<what> about N GB of memory and M GB are available; <advice>"`` when `needed` [bytes] does
    not fit."""
    free = available()
    if free is not None and needed > free:
        raise ValueError(f"{what} about {needed / 1e9:.3g} GB of memory and {free / 1e9:.3g} GB are available; {advice}")
