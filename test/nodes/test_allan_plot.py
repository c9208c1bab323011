"""
The allan node's live figure on ``imu/allan_plot/compressed``, over real DDS.

60 s of simulated 100 Hz data (white noise + bias instability on every axis) are fed to the
built node (``nodes/allan_feed.py``).  While nothing subscribes to the image topic the node
renders nothing (its ``/diagnostics`` count ``plots_published`` stays 0 over several publish
cycles); once this process subscribes, a PNG arrives, decodes to the figure's size and is not
blank.  About 20 s on the 2-core test machine, mostly node start-up and rendering.
"""

import io
import os
import shutil

from conftest import DOMAIN
from nodes.allan_feed import AllanFeed, status_values
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')


@pytest.mark.slow
def test_figure_published_only_while_subscribed(ros_context, tmp_path):
    """No render without a subscriber; then a non-blank PNG of the LiveFigure's size."""
    from imu_allan.report.plots import LiveFigure
    import matplotlib.image
    from sensor_msgs.msg import CompressedImage

    with AllanFeed(ros_context, DOMAIN) as feed:
        done = feed.feed()

        # Three publish cycles (0.5 s apart) after all samples, nobody subscribed: no image.
        def later_cycles():
            return sum(when > done for when, _ in feed.diags) >= 3
        assert feed.spin_until(later_cycles, 20)
        published = {status_values(m, 'IMU stream')['plots_published'] for _, m in feed.diags}
        assert published == {'0'}

        images = []
        feed.node.create_subscription(CompressedImage, 'imu/allan_plot/compressed',
                                      images.append, 1)
        assert feed.spin_until(lambda: images, 60), 'no image while subscribed'
        msg = images[0]
        assert msg.format == 'png'
        png = bytes(msg.data)
        assert png[:8] == b'\x89PNG\r\n\x1a\n'
        pixels = matplotlib.image.imread(io.BytesIO(png), format='png')
        width, height = LiveFigure().size_px
        assert pixels.shape[:2] == (height, width)
        gray = pixels[..., :3].mean(axis=2)
        # Not blank: a white figure with curves, text and bands has a clear spread of grey
        # levels (a blank or single-colour image has none); and at least 2 % of the pixels
        # are ink (darker than the light grid lines).
        assert gray.std() > 0.05, gray.std()
        assert np.mean(gray < 0.8) > 0.02
        path = tmp_path / 'allan_plot.png'
        path.write_bytes(png)
        keep = os.environ.get('IMU_ALLAN_KEEP_PLOT')  # to look at it: docs/online.md
        if keep:
            shutil.copy(path, keep)

        def reported():
            values = status_values(feed.diags[-1][1], 'IMU stream')
            return int(values['plots_published']) >= 1 and values['plot_render_s'] != 'nan'
        assert feed.spin_until(reported, 20)
