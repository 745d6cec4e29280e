"""The pytest kit: the ``odocan_rig`` fixture and the rig session behind it."""
