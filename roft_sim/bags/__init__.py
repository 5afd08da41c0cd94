"""ROS 2 bags (MCAP): a sequence under faults as a bag of standard messages, a run's estimates as
a bag, and the scoring of a bag recorded from a tracker (docs/bags.md).

Needs the optional extra ``bags`` (``mcap``, ``mcap-ros2-support``; ``rosbags`` for the tests'
second reader). Sits above :mod:`roft_sim.harness`, whose observation stream and metrics it
reuses; nothing but the CLI imports it.
"""
