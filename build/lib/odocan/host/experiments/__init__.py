"""Experiments with the firmware navigating in the closed-loop rig, measured from the ground truth.

* ``drive``: one power cycle of the robot; the host configures it over CAN (ODOM_CONFIG) and
  sends NAV_GOAL paths, hears NAV_STATUS / ODOM_ACK / the on-board pose / the encoder counts, and
  stamps every navigation state change with the true pose.
* ``seed002``: Valencia et al. (2009), Tables 1 and 2 (1 m straight, 80 cm square).
* ``umbmark``: Borenstein & Feng's UMBmark (4 m square both ways), the E_d / E_b estimates and
  the calibration written into the firmware.
* ``render``: the rich tables; ``options``: the shared command-line options; ``seeding``: the
  per-run seeds.
"""
