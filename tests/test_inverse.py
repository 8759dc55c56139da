"""A short run of scripts/inverse_rendering.py (issue 14): from parameters
30% off, the loss falls and every parameter moves towards the truth (the full
run, 200 steps, reaches 1%: docs/inverse.md).

Run: make core plugin && .venv/bin/python -m pytest tests/test_inverse.py
"""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import inverse_rendering  # noqa: E402


@pytest.mark.parametrize('case', sorted(inverse_rendering.CASES))
def test_short_inverse_rendering_moves_towards_the_truth(case, tmp_path):
    steps = 25
    r = inverse_rendering.optimise(case, steps, log=lambda *a: None)
    losses = [h[0] for h in r['history']]
    # The grating's loss has a noise floor near 5e-3 (each gradient pass draws
    # its own wavelengths; docs/inverse.md): a fall of 3x from 0.31 is the
    # signal there, 10x for the Gaussian.
    fall = 0.1 if case == 'gaussian' else 0.33
    assert max(losses[-5:]) < fall * losses[0], losses
    for k, truth in r['truth'].items():
        start_error = abs(r['start'][k] / truth - 1)
        end_error = abs(r['history'][-1][1][k] / truth - 1)
        assert end_error < 0.5 * start_error, (k, start_error, end_error)
    inverse_rendering.write_pictures(case, r, str(tmp_path))
    assert os.path.exists(tmp_path / ('%s_convergence.png' % case))
