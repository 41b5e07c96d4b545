"""Reading and writing calibration, measurement and error-table files."""
