"""
The ``fleet`` command's per-IMU trend plot (matplotlib, Agg backend).

One PNG per ``imu_id``: a 2 x 2 grid, rows gyroscope and accelerometer, columns white noise N
and bias instability B, against the record's start time (UTC).  Each axis (x red, y green,
z blue) is drawn with its 68.3 % intervals as error bars; the worst axis of each record is the
black line; records where a term was not detected show their 95 % upper limit as a hollow
down-triangle; flagged latest values are ringed in red.  Values are in conventional units
(deg/sqrt(h), deg/h, m/s/sqrt(h), m/s/h), the SI unit is named in the panel title.
"""

import matplotlib

matplotlib.use('Agg')
import matplotlib.dates as mdates  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .plots import AXIS_COLORS  # noqa: E402
from ..core.units import AXES, conventional, si_unit  # noqa: E402
from ..history.trends import SENSORS, TREND_TERMS, WORST  # noqa: E402

_NAMES = {'gyro': 'gyroscope', 'accel': 'accelerometer'}


def plot_imu(path, imu):
    """Write the trend figure of one :class:`~imu_allan.history.trends.Imu` to ``path``."""
    fig, grid = plt.subplots(2, 2, figsize=(11.0, 7.0), dpi=100, sharex=True)
    for row, sensor in enumerate(SENSORS):
        axes = [a for a in AXES if a.startswith(sensor)]
        for col, term in enumerate(TREND_TERMS):
            ax = grid[row][col]
            factor, unit = conventional(axes[0], term, 1.0)
            for axis in axes:
                s = imu.series.get((sensor, term, axis))
                if s is None:
                    continue
                color = AXIS_COLORS[axis[-1]]
                if s.value:
                    v = np.asarray(s.value) * factor
                    err = np.vstack([v - np.asarray(s.low) * factor,
                                     np.asarray(s.high) * factor - v])
                    ax.errorbar(s.start, v, yerr=err, fmt='o-', ms=3, lw=0.7, elinewidth=0.8,
                                capsize=2, color=color, alpha=0.6, label=axis)
                if s.limit:
                    ax.plot(s.limit_start, np.asarray(s.limit) * factor, 'v', ms=6,
                            mfc='none', color=color, alpha=0.6)
            worst = imu.series.get((sensor, term, WORST))
            if worst is not None:
                ax.plot(worst.start, np.asarray(worst.value) * factor, '-', color='black',
                        lw=1.6, label='worst axis', zorder=3)
            for flag in imu.flags:
                if flag['sensor'] == sensor and flag['term'] == term:
                    ax.plot([np.datetime64(flag['start_utc'])], [flag['value'] * factor], 'o',
                            ms=13, mfc='none', mec='red', mew=2.0, zorder=4)
            ax.set_title(f'{_NAMES[sensor]} {term.replace("_", " ")} '
                         f'{TREND_TERMS[term]} (SI: {si_unit(axes[0], term)})', fontsize=9)
            ax.set_ylabel(unit)
            ax.grid(True, color='0.9', lw=0.5)
            if ax.has_data():
                ax.legend(fontsize=7, loc='best')
            else:
                ax.text(0.5, 0.5, 'not detected in any record', ha='center',
                        transform=ax.transAxes, color='0.5')
    for ax in grid[1]:
        ax.xaxis.set_major_formatter(mdates.DateFormatter('%Y-%m-%d'))
        ax.tick_params(axis='x', labelrotation=30, labelsize=8)
    n_flags = len(imu.flags)
    status = f'{n_flags} flag(s), ringed red' if n_flags else 'no flag'
    fig.suptitle(f'{imu.imu_id}: {len(imu.records)} static records, 68.3 % intervals, '
                 f'{status}', fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
