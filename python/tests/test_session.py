# lidef.Session: a solver kept between calls; each solve starts from the last certified map.
import numpy as np
import pytest

import lidef
from conftest import SMALL


def test_dragging_in_two_steps_starts_the_second_from_the_first(beam, bend):
    s = lidef.Session(beam, **SMALL)
    s.set_handles(bend.sources)
    # Handles stay where the current map (the identity) takes them until solve() moves them.
    np.testing.assert_allclose(s.coefficients, beam.identity(), atol=1e-12)
    half = bend.sources + 0.5 * (bend.targets - bend.sources)
    first = s.solve(half)
    assert first.certified and first.handles_reached
    np.testing.assert_allclose(s.coefficients, first.coefficients)
    second = s.solve(bend.targets)
    assert second.certified and second.handles_reached
    # The session's history goes on: the second result's iterations include the first's.
    assert second.iterations > first.iterations
    f, _ = beam.evaluate(second.coefficients, bend.sources)
    assert np.abs(f - bend.targets).max() == pytest.approx(second.max_handle_error, abs=1e-7)


def test_session_input_errors(beam, bend):
    s = lidef.Session(beam, **SMALL)
    with pytest.raises(lidef.InputError, match="^targets: no handles"):
        s.solve(bend.targets)
    s.set_handles(bend.sources)
    with pytest.raises(lidef.InputError, match="^targets: has 2 rows but the session has 10 handles"):
        s.solve(bend.targets[:2])
    with pytest.raises(lidef.InputError, match="^max_iterations: "):
        lidef.Session(beam, max_iterations=-1)
