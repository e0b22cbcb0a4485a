"""Camera calibration: the `raingauge calibrate` wizard and the shipped camera profiles."""
