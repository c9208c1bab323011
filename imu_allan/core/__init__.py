"""ROS-free numerics: Allan deviation, confidence intervals, noise terms, fit, simulation."""
