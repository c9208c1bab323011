"""ROS-free input and output: device protocol, serial link, bags, logs and CSV."""
