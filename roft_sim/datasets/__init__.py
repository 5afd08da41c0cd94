"""Datasets on disk (fast-ycb, bop, hdf5) behind one lazy ``Sequence`` reader interface."""

from roft_sim.datasets.base import GT_MASK_SET, DetectorPoses, InMemorySequence, Sequence

__all__ = ["GT_MASK_SET", "DetectorPoses", "InMemorySequence", "Sequence"]
