"""odocan firmware: an integer-only differential-drive odometry ECU, written as the C it stands for.

Standard library only, no floats, no true division; it sees the world through ``firmware.hal``.
"""
