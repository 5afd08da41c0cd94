"""Public test toolkit: hypothesis strategies, unit-bearing assertions and fixtures.

Importing this package does not import hypothesis; :mod:`roft_sim.testing.strategies` does.
"""

from roft_sim.testing.assertions import (
    assert_pose_close,
    assert_quat_close,
    assert_rotation_close,
    assert_twist_close,
)

__all__ = ["assert_pose_close", "assert_quat_close", "assert_rotation_close", "assert_twist_close"]
