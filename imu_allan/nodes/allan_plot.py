"""
The allan node's live figure on ``imu/allan_plot/compressed`` (sensor_msgs/CompressedImage).

The figure is :class:`imu_allan.report.plots.LiveFigure`: the Allan deviation panels
``analyze`` draws (measured points, 68.3 % bands, fitted model and terms), gyroscopes and
accelerometers side by side, as PNG (``format`` ``png``, the topic name image_transport,
rqt_image_view and Foxglove expect).  It is rendered only while something subscribes, in a
worker thread, so the timer that takes IMU messages never waits for matplotlib: the node hands
over the finished estimate of each publish cycle and the newest one wins.
"""

import math
import threading
import time

from sensor_msgs.msg import CompressedImage

TOPIC = 'imu/allan_plot/compressed'


def title(node_name, result):
    """Return the figure's title: node, record length and rate, time of the estimate (UTC)."""
    seconds = result.n_samples / result.rate_hz
    span = (f'{seconds / 3600:.2f} h' if seconds >= 3600 else f'{seconds / 60:.1f} min'
            if seconds >= 60 else f'{seconds:.1f} s')
    return (f'{node_name}: overlapping Allan deviation of {span} at {result.rate_hz:g} Hz '
            f'({result.n_samples} samples), 68.3 % bands, fitted terms; '
            f'{time.strftime("%H:%M:%S", time.gmtime())} UTC')


class PlotPublisher:
    """Renders and publishes the figure of the latest estimate, only while subscribed."""

    def __init__(self, node, topic=TOPIC):
        """Create the publisher (reliable, depth 1) and start the worker thread."""
        self._node = node
        self._pub = node.create_publisher(CompressedImage, topic, 1)
        self._cond = threading.Condition()
        self._job = None
        self._stop = False
        self.published = 0
        self.render_s = math.nan
        self._thread = threading.Thread(target=self._run, name='allan_plot', daemon=True)
        self._thread.start()

    def offer(self, result, fitted):
        """Hand over an estimate (AllanResult, FittedModel or None); False if unsubscribed."""
        if result is None or self._pub.get_subscription_count() == 0:
            return False
        with self._cond:  # the newest estimate replaces one not yet rendered
            self._job = (result, fitted, title(self._node.get_name(), result),
                         self._node.get_clock().now().to_msg())
            self._cond.notify()
        return True

    def stats(self):
        """Key values for /diagnostics: images published and the last render time (s)."""
        return {'plots_published': self.published, 'plot_render_s': self.render_s}

    def close(self):
        """Stop the worker (waits for a render in progress)."""
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(timeout=10.0)

    def _run(self):
        figure = None
        while True:
            with self._cond:
                while self._job is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                (result, fitted, text, stamp), self._job = self._job, None
            start = time.perf_counter()
            try:
                if figure is None:  # matplotlib is imported here, off the node's start-up
                    from ..report.plots import LiveFigure
                    figure = LiveFigure()
                msg = CompressedImage(format='png', data=figure.render(result, fitted, text))
                self.render_s = time.perf_counter() - start
                msg.header.stamp = stamp
                self._pub.publish(msg)
                self.published += 1
            except Exception as exc:  # noqa: BLE001 - a figure must never stop the node
                self._node.get_logger().warning(f'live figure not published: {exc}',
                                                throttle_duration_sec=60.0)
