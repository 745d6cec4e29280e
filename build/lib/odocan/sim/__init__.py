"""odocan sim: the hardware around the firmware (motors, encoders, ground truth, clocks, buses)."""
