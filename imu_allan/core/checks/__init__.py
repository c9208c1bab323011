"""
The checks of a record before its estimate: time stamps, outliers, warm-up.

* :mod:`.preprocess`: the timing report (rate, gaps, jitter) and Tukey's outlier fences;
* :mod:`.quantile_kernel`: the compiled exact quartiles of long records;
* :mod:`.stamp_order`: the rule for isolated out-of-order or repeated stamps (the node's too);
* :mod:`.warmup`: the start where the bias is still settling.
"""
