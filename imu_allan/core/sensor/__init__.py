"""
The sensor's own processing, measured from its samples (report.json ``sensor``).

* :mod:`.measure`: :func:`.measure.measure_sensor` and the live
  :class:`.measure.SensorAccumulator`: LSB, repeats, the filter's correlation, lines and
  resonances per axis, and the :class:`~..fit.tau_range.Processing` the fit takes;
* :mod:`.spectrum`: the Welch sums, the white part's fit and the line and resonance search.
"""
