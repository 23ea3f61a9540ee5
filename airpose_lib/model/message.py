"""Sizes of the network's parameter vectors and of the message the drones exchange.

A stage's message is this view's current body pose ``theta`` (21 body joints in 6D, 126 values)
and shape ``beta`` (10 values): 136 float32 numbers, 544 bytes. The network (``variants``), the
staged per-drone API (``staged``) and the runtime's wire format (``runtime.wire``) all size it
from here. Imports nothing (no torch), so a drone process can size its packets at start-up.
"""
from __future__ import annotations

__all__ = ["NUM_BODY_JOINTS", "THETA_DIM", "BETA_DIM", "MESSAGE_DIM"]

NUM_BODY_JOINTS = 21  # body joints the network predicts (the root is phi)
THETA_DIM = NUM_BODY_JOINTS * 6  # 126
BETA_DIM = 10
MESSAGE_DIM = THETA_DIM + BETA_DIM  # 136 float32 = 544 bytes per stage
