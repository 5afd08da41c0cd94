"""Sensor models applied to rendered or recorded data: depth noise, flow sources, simulated
networks. Each is a pure function of its inputs and an explicit ``rng``."""
