"""Messages that compare a percentage with a threshold never print the value equal to the threshold or across
it (trial7: "the design removes 10 % of the rest shape's difference ... less than min_progress 10 %" for
9.66 %)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mdsr_opt.core.quantities import percent_beside
from mdsr_opt.scenes.verdict import failure_cause
from mdsr_opt.synthesis.acceptance import difference_failure


def test_min_progress_message_prints_the_value_below_the_threshold():
    msg = difference_failure(0.9034, 100.0, rest_difference=1.0)  # removes 9.66 %, min_progress 10 %
    m = re.search(r"removes (\S+) % of the rest shape's .* less than min_progress 10 %", msg)
    assert m, msg
    assert float(m.group(1)) < 10.0 and float(m.group(1)) == pytest.approx(9.66, abs=0.05)
    cause = failure_cause("design too far from the target: " + msg)
    assert cause == f"too far from the target: removes {m.group(1)} % of the rest shape's difference, less than 10 %"


def test_max_difference_message_prints_the_value_above_the_threshold():
    msg = difference_failure(0.05004, 1.0, 0.05)  # 5.004 % of the size, max_difference 5 %
    m = re.search(r"is (\S+) % of the size .* more than max_difference 5 %", msg)
    assert m, msg
    assert float(m.group(1)) > 5.0
    assert failure_cause("design too far from the target: " + msg) == \
        f"too far from the target: {m.group(1)} % of size, more than max_difference 5 %"


@pytest.mark.parametrize("digits", [0, 2])
def test_percent_beside_keeps_the_side_of_the_threshold(digits):
    rng = np.random.default_rng(0)
    for t in (0.1, 0.05, 2.0 / 3.0):
        for v in t + rng.normal(0.0, 1e-3, 200):
            shown = float(percent_beside(v, t, digits))
            assert np.sign(shown - 100 * t) == np.sign(100 * v - 100 * t), (v, t, shown)
            assert shown == pytest.approx(100 * v, abs=0.5 * 10.0 ** -digits)
    assert percent_beside(0.5, 0.1, digits) == f"{50:.{digits}f}"  # far from it: the digits asked
