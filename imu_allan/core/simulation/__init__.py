"""
Simulated IMUs: a noise model's time series, a device's processing, simulators' terms.

* :mod:`.simulate`: :func:`.simulate.simulate`, every term with its analytic statistics;
* :mod:`.device_processing`: the 3DM-GX3-25's window, decimation and float32 output;
* :mod:`.noise_stream`: a noise stream that continues across blocks (``gx3_sim``);
* :mod:`.gauss_markov`: one Gauss-Markov bias in place of the terms Gazebo and PX4 cannot hold.
"""
