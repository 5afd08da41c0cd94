"""Shared settings of the property suite for our own trackers (tests/properties), imported as
``from property_settings import ...`` (a unique module name: every conftest.py of the suite is a
module named ``conftest``).

Example budgets: :func:`budget` gives the number of hypothesis examples of a test under the
active profile: the CI-sized default (``default`` profile of tests/conftest.py) or the long run
(``pytest --hypothesis-profile=thorough``).
"""

from __future__ import annotations

import dataclasses

from hypothesis import settings

from roft_sim.trackers.baselines import PoseOnlyUkfConfig
from roft_sim.trackers.roft import RoftConfig, VelocityKFConfig
from roft_sim.trackers.roft.config import PoseSyncConfig

HORIZON_FRAMES = 12
"""Buffer horizon of the ROFT configuration under test: shorter than the longest generated delays,
so the horizon rule is exercised inside the delay properties too."""

ROFT_TINY = RoftConfig(
    velocity=VelocityKFConfig(subsampling_stride=5),
    sync=PoseSyncConfig(horizon_frames=HORIZON_FRAMES),
)
"""ROFT for 64x48 images (the object covers ~200 pixels: a stride of 5 keeps the flow update
alive) with a 12-frame horizon."""

ROFT_NO_SYNC = dataclasses.replace(ROFT_TINY, use_pose_resync=False)
"""The "w/o pose sync." ablation: delayed poses fused at arrival (a mutation)."""

POSE_ONLY = PoseOnlyUkfConfig(sync=PoseSyncConfig(horizon_frames=HORIZON_FRAMES))
"""The pose-only UKF baselines (``pose-only-ukf``, ``naive-delay``) with the same horizon."""


def budget(default: int, thorough: int) -> int:
    """Examples for one test: ``thorough`` under ``--hypothesis-profile=thorough``, else
    ``default``."""
    return thorough if settings.get_current_profile_name() == "thorough" else default
