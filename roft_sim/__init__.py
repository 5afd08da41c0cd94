"""roft_sim: simulation harness and dataset generator for 6D object pose and velocity trackers."""

__version__ = "0.1.0"
