"""propwatch offline toolchain: simulator, propeller models, data sets, training, export, calibration."""
