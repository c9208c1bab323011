"""
The live figure (``LiveFigure``): PNG of the stated size, not blank, reusable.

``analyze``'s own plots (the same :func:`draw_adev`) are exercised by test/cli/test_analyze.py
through ``--out``.  5 min of simulated 100 Hz data, fixed seed; about 5 s (three renders).
"""

import io

from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.units import AXES
from imu_allan.report.plots import LiveFigure
import matplotlib.image
import numpy as np
import pytest

MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.0e-4, 'bias_instability': 8.0e-4},
                              'accel': {'white_noise': 8.0e-4, 'bias_instability': 1.5e-3}})


@pytest.fixture(scope='module')
def estimate():
    n, rate = 30_000, 100.0  # 5 min; two fixed terms keep the fit short (about 3 s)
    pipe = OnlineAllan(rate, axes=AXES, terms=['white_noise', 'bias_instability'])
    pipe.feed(np.arange(n) / rate, simulate(MODEL, n, rate, seed=8))
    result = pipe.result()
    return result, pipe.fit(result)


def _gray(png):
    pixels = matplotlib.image.imread(io.BytesIO(png), format='png')
    return pixels[..., :3].mean(axis=2)


def test_live_figure_size_content_and_reuse(estimate):
    result, fitted = estimate
    figure = LiveFigure(size_px=(900, 400))
    first = _gray(figure.render(result, fitted, 'first'))
    assert first.shape == (400, 900)
    # not blank: curves, bands and text give a spread of grey levels and some dark ink
    assert first.std() > 0.05 and np.mean(first < 0.5) > 0.005
    # Reused figure: the old artists are gone, so no estimate is drawn over another.  The
    # measured points alone (no fit) must be less ink than points + model + term lines.
    bare = _gray(figure.render(result, None, 'first'))
    assert bare.shape == first.shape
    assert np.mean(bare < 0.5) < np.mean(first < 0.5)
    again = _gray(figure.render(result, fitted, 'first'))
    np.testing.assert_array_equal(again, first)
