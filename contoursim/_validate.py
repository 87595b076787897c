"""One home for argument checks: positivity, finiteness, shapes, time bases.

Each check raises, with a message that names the parameter, :class:`TypeError`
for a value of the wrong type (text, a boolean, a complex number where a real
number is wanted) and :class:`ValueError` (or a subclass) for a wrong value of
the right type (negative, not finite, wrong shape), as python-control does; so
a bad value is reported where the user wrote it and never as a traceback from
inside numpy. Readers of files turn both into a
:class:`~contoursim.exceptions.ConfigError` naming the file and line.
"""

import datetime
from collections.abc import Mapping

import numpy as np

__all__ = ["as_xyz", "closest", "finite", "flag", "float_dtype", "positive", "positive_int", "nonnegative",
           "float_array", "finite_array", "Frozen", "mask", "read_only", "rounded_grid", "shown", "time_base", "within",
           "TimeStepError"]

#: The largest magnitude of a float [-]: a number written beyond it overflows to infinity.
FLOAT_MAX = float(np.finfo(float).max)


class TimeStepError(ValueError):
    """A time base has a bad step: not increasing, or not uniform.

    Parameters
    ----------
    message : str
        What is wrong.
    step : int
        Index k of the offending step ``t[k + 1] - t[k]``.
    """

    def __init__(self, message, step):
        self.step = step
        super().__init__(message)


def positive(name, value):
    """Return `value` as a float after checking it is a finite number > 0.

    Raises
    ------
    TypeError
        `value` is not a real number (text and booleans are not).
    ValueError
        `value` is not finite, or <= 0.
    """
    value = _finite_scalar(name, value)
    if value <= 0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return value


def nonnegative(name, value):
    """Return `value` as a float after checking it is a finite number >= 0.

    Raises
    ------
    TypeError
        `value` is not a real number.
    ValueError
        `value` is not finite, or < 0.
    """
    value = _finite_scalar(name, value)
    if value < 0:
        raise ValueError(f"{name} must be zero or positive, got {value!r}")
    return value


def finite(name, value):
    """Return `value` as a float after checking it is a finite number (any sign)."""
    return _finite_scalar(name, value)


def within(name, value, low, high, scale=1.0):
    """Return `value` times `scale` after checking it is a finite number and the product lies in [`low`, `high`].

    For a value a file gives in the unit of its key (``start_angle_deg``) that the program takes in
    another (rad, `scale` of the key's unit) within a range of its own (±1e6 rad): the range is checked
    on the value as the program takes it and said in the key's unit, with the value as given.

    Raises
    ------
    TypeError
        `value` is not a real number.
    ValueError
        `value` is not finite, or out of the range.

    Examples
    --------
    >>> within("run_angle_deg", 90, 1e-6, 2 * np.pi, scale=np.pi / 180) == np.pi / 2
    True
    >>> within("run_angle_deg", 400, 1e-6, 2 * np.pi, scale=np.pi / 180)
    Traceback (most recent call last):
    ValueError: run_angle_deg must lie within [5.72958e-05, 360], got 400
    """
    number = _finite_scalar(name, value)
    if not low <= number * scale <= high:
        limits = f"±{high / scale:g}" if low == -high else f"[{low / scale:g}, {high / scale:g}]"
        given = f"{number:g}" if float(f"{number:g}") == number else f"{number:.15g}"  # 4e+09, 360.0000001
        raise ValueError(f"{name} must lie within {limits}, got {given}")
    return number * scale


def shown(value):
    """`value` for a message, a long one cut short: ``'100000000000… (401 characters)'``.

    Parameters
    ----------
    value : object
        A number, or the text of one as a file wrote it.

    Returns
    -------
    str
    """
    try:
        text = value if isinstance(value, str) else repr(value)
    except ValueError:  # an int of more digits than Python turns into text (4300)
        return "a whole number of more than 4300 digits"
    return text if len(text) <= 24 else f"{text[:12]}… ({len(text)} characters)"


def _no_number(value):
    """A value that is no number, as a message says it: a file's date or time by its text, else :func:`shown`."""
    if isinstance(value, datetime.datetime):
        return f"the date and time {value.isoformat()}"
    if isinstance(value, (datetime.date, datetime.time)):
        return f"the {type(value).__name__} {value.isoformat()}"
    return shown(value)


def _finite_scalar(name, value):
    if isinstance(value, (str, bytes, bool, np.bool_)):  # float() would take "40" and True
        raise TypeError(f"{name} must be a number, got {value!r}")
    try:
        value = float(value)
    except OverflowError:  # an int beyond a float's range
        raise ValueError(f"{name} must be finite, got {shown(value)}: beyond ±{FLOAT_MAX:.4g}") from None
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {_no_number(value)}") from None
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def finite_array(name, value, ndim=None, shape=None, limit=None):
    """Return `value` as a float ndarray after checking it: :func:`float_array`, then its values.

    `name`, `value`, `ndim` and `shape` are those of :func:`float_array`;
    every value must be finite and, given `limit`, at most `limit` in
    magnitude.

    Raises
    ------
    TypeError
        `value` holds text, booleans or complex numbers.
    ValueError
        Wrong dimensions or shape, a non-finite value, or one beyond `limit`.
    """
    arr = float_array(name, value, ndim, shape)
    if not np.isfinite(arr).all():
        first = np.unravel_index(np.argmax(~np.isfinite(arr)), arr.shape)
        if arr.ndim == 0:  # a number: no index to name
            raise ValueError(f"{name} must be finite, got {arr[()]}")
        raise ValueError(f"{name} contains a non-finite value ({arr[first]}) at index {_index(first)}")
    if limit is not None and arr.size and max(arr.max(), -arr.min()) > limit:  # |arr| > limit, no (N, d) temporary
        first = np.unravel_index(np.argmax(np.abs(arr) > limit), arr.shape)
        if arr.ndim == 0:
            raise ValueError(f"{name} must lie within ±{limit:g}, got {arr[()]:g}")
        raise ValueError(f"{name} holds {arr[first]:g} at index {_index(first)}, beyond ±{limit:g}")
    return arr


def _index(first):
    """An array index as a user writes it: ``3`` for a 1-D array, ``(1, 2)`` for more dimensions."""
    return int(first[0]) if len(first) == 1 else tuple(map(int, first))


def float_array(name, value, ndim=None, shape=None):
    """Return `value` as a float ndarray after checking its type and shape (not its values).

    Parameters
    ----------
    name : str
        Parameter name used in error messages.
    value : array_like
        The values.
    ndim : int, optional
        Required number of dimensions.
    shape : tuple, optional
        Required shape; ``None`` entries match any length.

    Raises
    ------
    TypeError
        `value` holds text, booleans or complex numbers.
    ValueError
        Wrong dimensions or shape.
    """
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be numeric, got {value!r}")
    try:
        kind = np.asarray(value).dtype.kind
        if kind == "O" or (kind in "iuf" and not isinstance(value, np.ndarray)):  # a list mixing numbers and text, or
            # numbers and booleans, which numpy reads as numbers: [[true, 0], [10, 0]] as [[1, 0], [10, 0]]
            mixed = any(isinstance(v, (str, bytes, bool, np.bool_)) for v in np.asarray(value, object).flat)
            kind = "U" if mixed else "f" if kind == "O" else kind
        arr = np.asarray(value, dtype=float) if kind in "iuf" else None
    except OverflowError:  # an int beyond a float's range
        raise ValueError(f"{name} holds a number beyond ±{FLOAT_MAX:.4g}") from None
    except (TypeError, ValueError):
        arr = None
    if arr is None:
        raise TypeError(f"{name} must be numeric (not text, booleans or complex numbers)")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {arr.shape}")
    if shape is not None:
        if arr.ndim != len(shape) or any(
            want is not None and want != got for want, got in zip(shape, arr.shape)
        ):
            want = ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "")  # (3,)
            raise ValueError(f"{name} must have shape ({want}), got {arr.shape}")
    return arr


def read_only(array, given):
    """`array`, the checked form of the caller's `given`, made read-only for an object that keeps it.

    The caller's own array is never changed: one `array` shares memory with
    is copied first (setting its flag would make the caller's array read-only,
    and its values could later change under the object); one made from
    `given` (a list, another dtype) is frozen as it is; a read-only one is kept.

    Parameters
    ----------
    array : ndarray
        From :func:`float_array`, :func:`finite_array`, :func:`mask`, ...
    given : object
        What the caller passed.

    Returns
    -------
    ndarray
    """
    if array.flags.writeable:
        if isinstance(given, np.ndarray) and np.may_share_memory(array, given):
            array = array.copy()
        array.flags.writeable = False
    return array


class Frozen(Mapping):
    """A read-only mapping an object keeps (a copy of the caller's): unlike :class:`types.MappingProxyType` it
    pickles, deep-copies and hashes (where its values hash), so the objects holding one do too.

    Examples
    --------
    >>> import pickle
    >>> offset = Frozen({"x": 250.0})
    >>> pickle.loads(pickle.dumps(offset)) == offset == {"x": 250.0}
    True
    """

    __slots__ = ("_data",)

    def __init__(self, data=()):
        self._data = dict(data)

    def __getitem__(self, key):
        return self._data[key]

    def __iter__(self):
        return iter(self._data)

    def __len__(self):
        return len(self._data)

    def __hash__(self):
        return hash(frozenset(self._data.items()))

    def __repr__(self):
        return f"{type(self).__name__}({self._data!r})"

    def __reduce__(self):
        return type(self), (self._data,)


def mask(name, value, shape):
    """Return `value` as a boolean ndarray of `shape` after checking it holds booleans, or only the numbers 0 and 1.

    ``np.asarray(value, bool)`` would take any value as one (``"no"`` and NaN
    as true): a mask given something else is refused rather than read so.

    Raises
    ------
    TypeError
        `value` holds text or other objects.
    ValueError
        Wrong shape, or a number other than 0 and 1.
    """
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be booleans (or 0 and 1), got {value!r}")
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be booleans (or 0 and 1), got {arr.dtype} values")
    if arr.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    if arr.dtype.kind != "b":
        other = (arr != 0) & (arr != 1)  # NaN too
        if other.any():
            first = np.unravel_index(np.argmax(other), arr.shape)
            raise ValueError(f"{name} must be booleans (or 0 and 1), got {arr[first]} at index {_index(first)}")
        arr = arr.astype(bool)
    return arr


def time_base(name, t, rtol=1e-3):
    """Check that `t` is strictly increasing and uniformly sampled.

    Returns
    -------
    t : ndarray, shape (N,)
    dt : float
        The sample period [s]: the mean step, as the whole span gives it. A
        single step of a clock that reads large is known only to its
        rounding (at t ~ 1e5 s, 1 ms comes out 1.0000000038 ms).
    """
    t = finite_array(name, t, ndim=1)
    if t.size < 2:
        raise ValueError(f"{name} needs at least 2 samples, got {t.size}")
    step = np.diff(t)
    if np.any(step <= 0):
        i = int(np.argmax(step <= 0))
        raise TimeStepError(f"{name} must be strictly increasing: t[{i + 1}] = {t[i + 1]} follows t[{i}] = {t[i]}", i)
    dt = float(np.median(step, overwrite_input=True))  # reorders `step`: no (N,) copy
    np.subtract(t[1:], t[:-1], out=step)  # the steps again, in order
    step -= dt
    worst = int(np.argmax(np.abs(step, out=step)))  # the deviations from the median step, in place
    tolerance = rtol * max(dt, 1e-300) + 1e-12
    if step[worst] > tolerance:
        uneven = int(np.count_nonzero(step > tolerance))
        spread = (f" ({uneven} of its {step.size} steps are off the median by more than {rtol:.1%}, up to "
                  f"{step[worst] / dt:.1%}: a clock that jitters; resample to a uniform grid, or write the "
                  "logger's nominal times)" if uneven > 2 else "")  # one sample off makes two steps
        raise TimeStepError(
            f"{name} must be uniformly sampled: step {worst} is {t[worst + 1] - t[worst]:.9g} s, "
            f"the median step is {dt:.9g} s{spread}",
            worst,
        )
    return t, float((t[-1] - t[0]) / (t.size - 1))


def rounded_grid(t, unit):
    """The uniform grid ``t0 + k dt`` that the times `t` are, rounded to multiples of `unit`; None if there is none.

    A 3 kHz clock printed to the µs steps 333 and 334 µs, too unevenly for :func:`time_base`: every time lies within
    half a µs of a uniform grid, and no more is known of it. The grid is the one whose greatest deviation from `t` is
    least (the spread of ``t - k dt`` is convex in `dt`: a bounded search over the periods a grid so near can have).

    Parameters
    ----------
    t : ndarray, shape (N,)
        The times [s], N >= 2.
    unit : float
        The unit of the last decimal they are printed to [s] (1e-6 for ``0.000333``).

    Returns
    -------
    grid : ndarray, shape (N,)
        The grid [s].
    dt : float
        Its period [s].

    None instead when a time lies further than half a `unit` from every uniform grid (beyond the float rounding of
    `t`), or when the `unit` is over a tenth of the mean step (times printed to the ms, 0, 1, 2, 4, 5 ms with a
    sample missing, lie within half a ms of a grid at 800 Hz).
    """
    from scipy.optimize import minimize_scalar  # slow to import; only times printed short of their step need it

    k = np.arange(t.size)
    span = t - t[0]
    mean = span[-1] / (t.size - 1)
    if not 0 < unit <= mean / 10:
        return None
    reach = unit / (t.size - 1)  # a grid within half a unit of both ends steps within this of the mean step
    slack = 4 * float(np.spacing(max(abs(t[0]), abs(t[-1]))))  # the float rounding of a printed time, and of the grid

    def width(shift):  # the spread of the deviations from the grid of period mean + shift * reach, shift in [-1, 1]
        deviation = span - k * (mean + shift * reach)
        return deviation.max() - deviation.min()

    best = minimize_scalar(width, bounds=(-1.0, 1.0), method="bounded", options={"xatol": 1e-9})
    if best.fun > unit * (1 + 1e-6) + 2 * slack:  # the least spread, found to 1e-8 of a unit; a tie rounds by half one
        return None
    dt = mean + best.x * reach
    deviation = span - k * dt
    return t[0] + (deviation.max() + deviation.min()) / 2 + k * dt, float(dt)


def as_xyz(points):
    """Planar points (N, 2) with z = 0 appended, shape (N, 3); (N, 3) points unchanged."""
    points = np.asarray(points, dtype=float)
    return points if points.shape[1] == 3 else np.column_stack([points, np.zeros((len(points), 3 - points.shape[1]))])


def callback(name, value):
    """Return `value` after checking it is ``None`` or callable (a progress function): one given a number or a file
    name failed deep inside the work it was to follow ("'int' object is not callable").

    Raises
    ------
    TypeError
        `value` is neither.
    """
    if value is not None and not callable(value):
        raise TypeError(f"{name} must be a function (or None), got {value!r}")
    return value


def flag(name, value):
    """Return `value` after checking it is a boolean (``True``, ``False`` or numpy's).

    Python would take any value as one (``"no"`` and ``[0]`` as true, ``0.0``
    as false): a flag given something else is refused rather than read so.

    Raises
    ------
    TypeError
        `value` is not a boolean.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def closest(word, known):
    """``" (did you mean 'kp_per_s'?)"`` for a misspelt `word` among the names `known`; ``""`` when none is close.

    Parameters
    ----------
    word : object
        The name given (text; anything else matches nothing).
    known : iterable of str
        The names there are.

    Returns
    -------
    str

    Examples
    --------
    >>> closest("kp_per_sec", ["kv_A_s_per_m", "kp_per_s", "ti_s"])
    " (did you mean 'kp_per_s'?)"
    """
    import difflib

    match = difflib.get_close_matches(word, list(known), n=1, cutoff=0.75) if isinstance(word, str) else []
    return f" (did you mean {match[0]!r}?)" if match else ""


def float_dtype(name, value):
    """Return `value` as a numpy dtype after checking it is float64 or float32, the precisions results are kept in.

    float16 keeps 11 significant bits (a position of 500 mm to 0.25 mm), an
    integer type whole millimetres, and object or complex arrays hold no
    positions: each would return a wrong answer without a word.

    Raises
    ------
    ValueError
        `value` is not a dtype, or is another one.
    """
    try:
        dtype = np.dtype(value)
    except TypeError:
        dtype = None
    if dtype not in (np.float64, np.float32):
        raise ValueError(f"{name} must be float64 or float32, got {shown(value) if dtype is None else dtype}"
                         + (" (11 significant bits: a position of 500 mm to 0.25 mm)" if dtype == np.float16 else ""))
    return dtype


def positive_int(name, value, least=1):
    """Return `value` as an int after checking it is a whole number >= `least` (1 unless given).

    Raises
    ------
    TypeError
        `value` is not an integer (booleans are not; nor is 2.0 or "2").
    ValueError
        `value` is below `least`.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be a whole number, got {value!r}")
    if value < least:
        raise ValueError(f"{name} must be at least {least}, got {value}")
    return int(value)


def seed(name, value):
    """Return `value` as an int after checking it is a random seed: a whole number from 0 to 2**53 - 1 (exact as a
    float, as a trace's metadata holds it).

    Raises
    ------
    TypeError
        `value` is not an integer (booleans are not).
    ValueError
        `value` is negative or from 2**53 on.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be a whole number from 0 to 2**53 - 1, got {value!r}")
    if not 0 <= value < 2**53:
        raise ValueError(f"{name} must be a whole number from 0 to 2**53 - 1, got {value!r}")
    return int(value)


def commanded(at, n_points, n_samples):
    """The reference sample commanded at each of `n_points` actual points (`at`), checked; None for "point i at sample i".

    Parameters
    ----------
    at : array_like of int, shape (n_points,), or None
        Sample indices in [0, n_samples); None is allowed when there is one point per sample.
    n_points, n_samples : int
        Actual points, reference samples.

    Returns
    -------
    ndarray of int, shape (n_points,), or None
    """
    if at is None:
        if n_points != n_samples:
            raise ValueError(f"actual has {n_points} rows but the reference {n_samples} samples: give `at`, "
                             "the sample commanded at each actual point")  # fmt: skip
        return None
    at = np.asarray(at)
    if at.size == 0:  # [] is read as floats
        at = at.astype(np.int64)
    if at.shape != (n_points,):
        raise ValueError(f"at must hold one sample index per actual point ({n_points}), got shape {at.shape}")
    if at.dtype.kind not in "iu":
        raise ValueError(f"at must hold whole sample indices, got {at.dtype} values")
    outside = np.flatnonzero((at < 0) | (at >= n_samples))
    if outside.size:
        raise ValueError(f"at[{outside[0]}] = {at[outside[0]]} is not a sample index of the reference's "
                         f"{n_samples} samples (0 to {n_samples - 1})")
    return at
