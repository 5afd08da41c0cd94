"""torch ``Dataset`` s over roft_sim data (optional extra: ``pip install -e '.[torch]'``).

- :class:`SequenceDataset`: map-style, one item per frame of one or more sequences in any of our
  formats (fast-ycb, bop, hdf5) or the real Fast-YCB.
- :class:`GeneratorDataset`: an ``IterableDataset`` that renders scenarios on the fly (one
  OpenGL context per DataLoader worker, created in the worker; scenario ``i`` gets the seed
  ``SeedSequence(seed, spawn_key=(i,))``, so the stream is the same whatever the number of
  workers).
- :func:`collate`: stacks a batch, padding images and masks of different sizes and marking
  missing entries (a detector miss).

An item is a dict (docs/torch.md, shapes and units):

=================  ===========================  ============================================
``rgb``            uint8 (3, H, W)              the image, RGB, channels first
``depth``          float32 (1, H, W)            z-depth [m], 0 = no measurement
``mask``           bool (H, W)                  ground-truth visible mask (absent if none)
``detector_mask``  bool (H, W) or None          the chosen detector mask set; None = a miss
``flow``           float32 (2, Hg, Wg)          ``F_k`` (frame k-1 -> k) ``(du, dv)`` [px];
                                                zeros for k = 0
``flow_valid``     bool (Hg, Wg)                False where the vector is not meaningful
                                                (everywhere for k = 0)
``pose``           float64 (4, 4)               ground-truth ``T_cam_obj`` [m]
``velocity``       float64 (6,)                 ``v_obj`` [m/s] and ``w`` [rad/s], camera
                                                frame (docs/conventions.md)
``intrinsics``     float64 (3, 3)               pinhole ``K`` [px]
``k``              int64 ()                     frame index in its sequence
``t_s``            float64 ()                   time stamp [s]
``sequence``       str                          sequence name
=================  ===========================  ============================================

Without ground truth (a real recording) ``pose`` and ``velocity`` are NaN.
"""

from __future__ import annotations

from roft_sim.torch.datasets import (
    GeneratorDataset,
    SequenceDataset,
    collate,
    sample_from_frame,
)

__all__ = ["SequenceDataset", "GeneratorDataset", "collate", "sample_from_frame"]
