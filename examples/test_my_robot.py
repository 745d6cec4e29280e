"""The odocan pytest plugin as a user writes it: the README's complete example.

Runs against our firmware in lockstep by default, and unchanged against any firmware that speaks
the DBC with ``pytest --odocan-bus "interface=udp_multicast,channel=239.74.163.9,hop_limit=0"``.
"""

import math

import pytest

# Borenstein's E_d = 1.002 (right wheel 0.2 % larger than the left, mean kept) on pmir (wheelbase
# b = 0.30 m): over D metres of straight driving the true heading drifts from the on-board one by
# 2 (E_d - 1) / (E_d + 1) D / b = 6.7 mrad per metre, and the position by about D^2 / 2 times that
# sideways. The goal below is 1.12 m away: 7.5 mrad and 4.2 mm, plus the encoders' quantisation
# (pmir: 0.94 mm and 3.1 mrad per count) -> bounds of 10 mm and 15 mrad.
ERRORS = "ed=1.002"
NEAR_TRUTH_M = 0.010
NEAR_TRUTH_RAD = 0.015
ONE_LSB_M = 1e-4  # ODOM_POSE_X/Y resolution: 0.1 mm


@pytest.mark.odocan(robot="pmir", integrator="exact")
def test_navigates_to_a_goal_with_exact_odometry(odocan_rig):
    rig = odocan_rig(errors=ERRORS, seed=1)
    goal = rig.goto(1.0, 0.5, heading_rad=math.pi / 2, mode="turn_go_turn")
    rig.run_until_reached(goal, timeout_s=30)

    status = rig.nav_status
    assert status["GOAL_ID"] == goal
    assert status["STATE"] == "REACHED"
    x, y, heading = rig.pose
    assert math.hypot(x - 1.0, y - 0.5) <= 0.005  # the firmware's position tolerance: 5 mm
    assert abs(heading - math.pi / 2) <= 0.0088  # its heading tolerance: 0.5 degree (+ 1 LSB)
    rig.assert_pose_matches_reference(position_m=ONE_LSB_M)
    rig.assert_near_truth(position_m=NEAR_TRUTH_M, heading_rad=NEAR_TRUTH_RAD)


@pytest.mark.odocan(integrator="rk2")
def test_lost_encoder_frames_cost_no_precision(odocan_rig):
    rig = odocan_rig(faults="drop=0.02,seed=3")
    rig.drive("straight", seconds=3.0)

    assert rig.pose.x_m > 1.0
    assert rig.report()["e2e"]["WHEEL_ENCODERS"]["lost"] > 0  # frames were lost on the bus
    rig.assert_pose_matches_reference(position_m=ONE_LSB_M)
    assert rig.odom_status["STATE"] == "OK"
