"""
Command-line entry points (analyze, discrepancy, gx3_sim).

Importing this package is what starting a command does, so it sets the process-wide BLAS
default here (before numpy loads): the fits solve many small (< 100 x 100) systems, where BLAS
threads only add overhead; on a 2-core robot computer they were measured to make them 15x
slower.  A default, not a rule: a value already in the environment wins.
"""

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
