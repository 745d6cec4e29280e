"""Bytes in and out: CAN logs (candump, ASC, BLF), opening python-can buses."""
