"""Offscreen MuJoCo rendering of rgb, depth and segmentation, and exact ground truth."""
