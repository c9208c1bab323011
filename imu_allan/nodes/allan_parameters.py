"""
The allan node's parameters: names, defaults, descriptions and ranges, and the timing constants.

One table (:class:`~imu_allan.nodes.common.Param` rows) declares them with descriptors and
checks every set; :func:`imu_allan.core.live.session.check_parameters` checks them as a whole
and :func:`~imu_allan.core.live.session.pipeline_options` maps them to the estimator's
options.  docs/interfaces.md lists them.
"""

from .common import Param

DESCRIPTION = ('Live Allan deviation and noise coefficients (with 68.3 % intervals) of '
               'imu/data_raw: publishes imu/allan_coeffs, imu/allan_deviation and '
               '/diagnostics against a noise budget. Bounded memory; moving spans left out.')

#: The parameter table (nodes.common.Param: name, default, description, range, read-only).
PARAMETERS = [
    Param('rate_hz', 0.0, 'sample rate of imu/data_raw, Hz (tau0 = 1/rate_hz); 0 = measured '
                          'from the header stamps (median spacing over the first 2 s)',
          (0.0, 10000.0)),
    Param('filter_window_s', 0.0, 'length of the moving average the IMU applies before it '
                                  'outputs, s (3DM-GX3-25: the driver parameter filter_window '
                                  '/ 1000 Hz, shown on its /diagnostics); 0 = unknown: '
                                  'measured from the data', (0.0, 1.0), read_only=True),
    Param('publish_period', 10.0, 'seconds between publications (each cycle computes intervals '
                                  'and fits one axis at a time between message drains)',
          (0.1, 3600.0)),
    Param('window_s', 0.0, 'sliding window, s: publish the estimate of the last window_s seconds '
                           '(0 = the whole run)', (0.0, 1.0e7)),
    Param('max_tau', 10000.0, 'longest averaging time tracked, s (fixes the memory)',
          (0.001, 1.0e7)),
    Param('points_per_decade', 10, 'averaging times per decade', (1, 100)),
    Param('stride_base', 256, 'averaging factors up to this are exact; longer ones use every '
                              's-th overlapping term (docs/online.md)', (1, 10_000_000)),
    Param('min_clusters', 10, 'publish an averaging time once the data span min_clusters x tau',
          (2, 10000)),
    Param('estimators', ['oadev'], 'deviations computed (string array or comma list of oadev, '
                                   'mdev, ohdev; oadev always): each other kind is published on '
                                   'imu/allan_deviation/<kind>, same layout as '
                                   'imu/allan_deviation'),
    Param('gate', True, 'leave spans where the IMU moves out of the estimate'),
    Param('gate_window_s', 0.2, 'stationarity gate window, s', (0.005, 60.0)),
    Param('gate_std_factor', 3.0, 'motion if a window std exceeds this x the noise floor',
          (1.1, 1000.0)),
    Param('gate_step_factor', 8.0, 'motion if a window mean jumps by this many sigmas',
          (0.5, 1000.0)),
    Param('gate_gyro_max', 0.1, 'motion if the mean angular rate exceeds this, rad/s',
          (1.0e-6, 100.0)),
    Param('gate_hold_s', 1.0, 'seconds left out after motion (settling)', (0.0, 600.0)),
    Param('gap_factor', 1.5, 'a stamp spacing above this many sample intervals is a gap (the '
                             'phase restarts)', (1.01, 1000.0)),
    Param('terms', '', 'comma-separated terms to fit (empty: automatic among the five IEEE '
                       'terms)'),
    Param('budget_file', '', 'noise budget YAML (empty: the packaged 3DM-GX3-25 datasheet '
                             'budget)'),
    Param('model_file', '', 'noise model YAML for a model-vs-data discrepancy check (optional)'),
    Param('timeout_s', 2.0, 'ERROR on /diagnostics after this many seconds without samples',
          (0.01, 3600.0)),
    Param('rate_tolerance', 0.1, 'WARN when the measured rate differs by more than this fraction',
          (0.0, 10.0)),
    Param('hardware_id', '', 'hardware_id of the diagnostic statuses'),
    Param('covariance_topic', '', 'republish every imu/data_raw message here with the angular-'
                                  'velocity and linear-acceleration covariance diagonals set to '
                                  'the live per-sample variance N^2 rate_hz (the driver values '
                                  'until the first estimate; empty: off; read-only)',
          read_only=True),
    Param('covariance_mode', 'raw', 'covariance_topic variances: raw (N^2 rate_hz of the fitted '
                                    'white noise) or overbound (the white noise whose Allan '
                                    'variance is at or above the measured upper 95 % bound at '
                                    'every published averaging time; docs/exports.md)',
          choices=('raw', 'overbound')),
    Param('targets', '', 'recording advice targets TERM=REL,...: relative 68.3 % half-widths '
                         'over the defaults (white_noise=0.02, bias_instability=0.10, others '
                         '0.25)'),
    Param('advice_period', 60.0, 'seconds between recording-advice updates, and one whenever '
                                 'the record has doubled (each costs about a second of CPU, '
                                 'run in steps between drains)',
          (0.1, 86400.0)),
    Param('drain_period', 0.0, 'seconds between taking the queued messages (read-only); 0 = '
                               '0.1, or 0.05 with covariance_topic set (its republish delay)',
          (0.0, 1.0), read_only=True),
    Param('change_window_s', 600.0, 'change test window, s: dynamic Allan variance over windows '
                                    'of this length, step a quarter, each against the pooled '
                                    'baseline before it (docs/online.md); 0 = off',
          (0.0, 1.0e6)),
    Param('change_hold_s', 0.0, 'seconds (of header stamps) a change WARN lasts; 0 = until '
                                'change_reset is set', (0.0, 1.0e7)),
    Param('change_reset', False, 'any set of this parameter (true or false) clears the change '
                                 'WARNs and restarts the baselines'),
    Param('queue_depth', 5000, 'subscription queue depth, messages (read-only; >= rate x '
                               'drain_period x a margin)', (10, 1_000_000), read_only=True),
]
_DEFAULTS = {p.name: p.default for p in PARAMETERS}
#: Default seconds between drains (:func:`drain_period`), without / with covariance_topic.
DRAIN_S, DRAIN_COVARIANCE_S = 0.1, 0.05
#: Seconds between feeds of the messages taken (decoded and fed in one batch): each numpy
#: call costs 5-15 us on the cache-cold data of a drain, so a quarter second of 50-ms drains
#: fed as one costs about 40 % as much (docs/benchmarks.md).  Everything taken is fed before
#: a publish cycle starts, before its diagnostics and before a parameter change: what is
#: published is the same.
FEED_PERIOD_S = 0.25
#: imu/temperature queue depth, messages (taken every drain; the driver sends 1 a second).
TEMPERATURE_DEPTH = 100
#: Longest stretch of publish-cycle work done in one drain callback, as a share of the drain
#: period (a step may overrun it): 20 ms of 50, 40 ms of 100, so a cycle and the advice take
#: the same wall time whatever the period.
STEP_SHARE = 0.4


def drain_period(p):
    """
    Seconds between drains: ``drain_period``, or with 0 the default for ``covariance_topic``.

    Each drain wakes the executor, whose wait set is built anew in Python every time (about
    1 ms of CPU on this machine's cache-cold data, docs/benchmarks.md): at 1 kHz 0.1 s costs
    a point and a half of a core less than 0.05 s.  A republished stream (``covariance_topic``)
    keeps 0.05 s, the delay a filter downstream sees.
    """
    if p['drain_period'] > 0:
        return p['drain_period']
    return DRAIN_COVARIANCE_S if p['covariance_topic'] else DRAIN_S
