"""The shared argument checks: text and booleans are not numbers, time-base problems carry their step."""

import datetime
import re

import numpy as np
import pytest

from contoursim import _validate


@pytest.mark.parametrize("check", [_validate.positive, _validate.nonnegative])
@pytest.mark.parametrize("value", ["40", b"40", True, np.True_])
def test_scalar_checks_refuse_text_and_booleans(check, value):
    # float("40") == 40.0 and float(True) == 1.0: the checks must not let them through
    with pytest.raises(TypeError, match=f"kp must be a number, got {value!r}"):
        check("kp", value)


@pytest.mark.parametrize("value, said", [
    (datetime.date(1979, 5, 27), "the date 1979-05-27"), (datetime.time(7, 32), "the time 07:32:00"),
    (datetime.datetime(1979, 5, 27, 7, 32, tzinfo=datetime.timezone.utc), "the date and time 1979-05-27T07:32:00+00:00"),
    ([1.0, 2.0], "[1.0, 2.0]"), (list(range(100)), "[0, 1, 2, 3,… (390 characters)")])
def test_scalar_checks_say_a_date_as_written_and_cut_a_long_value_short(value, said):
    """A TOML date for a number was said as its repr: "feed_mm_min must be a number, got datetime.date(1979, 5, 27)"."""
    with pytest.raises(TypeError) as info:
        _validate.positive("feed_mm_min", value)
    assert str(info.value) == f"feed_mm_min must be a number, got {said}"


def test_scalar_checks_take_numbers():
    assert _validate.positive("kp", np.int64(40)) == 40.0
    assert _validate.nonnegative("vff", 0) == 0.0


@pytest.mark.parametrize("value", ["1.5", ["1", "2"], [True, False], np.array([1.0 + 2.0j]),
                                   np.array([1.0, "a"], object),
                                   # a boolean among numbers, which numpy reads as a number: a path file's points_mm =
                                   # [[true, 0], [10, 0]] ran from x = 1
                                   [[True, 0], [10, 0]], [0.5, False], (np.True_, 2)])
def test_array_check_refuses_text_booleans_and_complex(value):
    with pytest.raises(TypeError, match="travel must be numeric"):
        _validate.finite_array("travel", value)


def test_array_check_takes_integers_and_lists():
    np.testing.assert_array_equal(_validate.finite_array("travel", [0, 200]), [0.0, 200.0])
    np.testing.assert_array_equal(_validate.finite_array("poly", np.array([1, 2.5], object)), [1.0, 2.5])


@pytest.mark.parametrize(
    "t, step, words",
    [([0.0, 1.0, 2.0, 1.5, 4.0], 2, "strictly increasing: t[3] = 1.5 follows t[2] = 2.0"),
     ([0.0, 1.0, 2.0, 3.0, 5.0, 6.0], 3, "uniformly sampled: step 3 is 2 s")],
)
def test_time_base_names_the_bad_step(t, step, words):
    with pytest.raises(_validate.TimeStepError, match=re.escape(words)) as info:
        _validate.time_base("t", t)
    assert info.value.step == step
