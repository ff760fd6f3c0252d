"""Where the solvers stop over a piecewise-constant profile."""

import numpy as np

from pymc_vcc.physics.integration.stops import segment_stops, stop_plan


def test_each_output_time_belongs_to_one_segment_and_each_segment_ends_on_a_stop():
    """Segments [0, 10), [10, 25], outputs every 5 s: 10 s starts the second segment (stored
    before it runs), 25 s ends the last; the first segment's end is a stop of no row."""
    times = np.arange(0.0, 26.0, 5.0)
    held = np.array([[1.0], [2.0]])
    plan = stop_plan(np.array([0.0, 10.0, 25.0]), held, times, np.zeros(1))
    assert plan.times.tolist() == [5.0, 10.0, 15.0, 20.0, 25.0]
    assert plan.rows.tolist() == [1, -1, 3, 4, 5]
    assert plan.starts.tolist() == [0, -1, 1, -1, -1]
    assert plan.start_rows.tolist() == [0, 2]
    assert [stops.tolist() for stops in segment_stops(plan, 0)] == [[5.0], [1]]
    assert [stops.tolist() for stops in segment_stops(plan, 1)] == [[15.0, 20.0, 25.0], [3, 4, 5]]
