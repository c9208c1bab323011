"""
Thin rclpy nodes: parameters, QoS, timers and publishing; the numerics live in core/.

Importing this package is what starting a node does, so it sets the process-wide BLAS default
here, before numpy loads (see :mod:`imu_allan.cli` for why); a value already set wins.
"""

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
