"""
Has the noise changed?  The dynamic Allan deviation and the change test.

* :mod:`.dynamic`: the Allan deviation over sliding windows (``analyze --dynamic``);
* :mod:`.detection`: the sequential change test with its measured false-alarm rate (used
  offline and by the node's :mod:`..live.change_monitor`).
"""
