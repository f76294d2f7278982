"""Propagation engine: every transmitter-to-receiver path through a scene."""
