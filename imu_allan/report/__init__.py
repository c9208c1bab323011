"""Reports: report.json and console text, plots, Kalibr and the thesis CSV, topic layouts."""
