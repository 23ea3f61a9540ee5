"""Per-drone execution in stages, with only the 136-number messages between drones.

On a drone, stage 1 is the backbone plus the first regressor iteration and stages 2 and 3 are one
iteration each. After every stage the drone sends its message (21 x 6D body pose + 10 betas) and
waits for the other drones' messages before the next stage::

    node = DroneNode(model)                        # one per drone (process, machine)
    m1 = node.stage1(image, P)                     # -> (136,) float32, send it
    m2 = node.stage(2, [m1_from_other_drone])      # -> send
    m3 = node.stage(3, [m2_from_other_drone])      # final estimate (sending it is optional)
    out = node.result()                            # this view's outputs, batch 1

The messages are plain numpy arrays, so any transport works; :func:`encode_message` /
:func:`decode_message` give the wire format (little-endian float32, 544 bytes, or float16, 272
bytes). For Baseline and Fullcam the other drones' messages are ignored. A multi-view node given
no messages (lost link) uses the mean parameters as the "other view", as in iteration 1.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .message import BETA_DIM, MESSAGE_DIM, NUM_BODY_JOINTS, THETA_DIM
from .variants import AirPoseNet

__all__ = ["encode_message", "decode_message", "message_nbytes", "fuse_message_list", "DroneNode"]

_WIRE = {"float32": np.dtype("<f4"), "float16": np.dtype("<f2")}


def _wire_dtype(dtype) -> np.dtype:
    name = np.dtype(dtype).name
    if name not in _WIRE:
        raise ValueError(f"message dtype must be float32 or float16, got {name}")
    return _WIRE[name]


def message_nbytes(dtype="float32") -> int:
    """Bytes of one message on the wire: 544 (float32) or 272 (float16)."""
    return MESSAGE_DIM * _wire_dtype(dtype).itemsize


def encode_message(theta6d, beta, dtype="float32") -> np.ndarray:
    """Pack one view's body pose and shape into a message.

    Args:
        theta6d: ``(21, 6)`` or ``(126,)`` (numpy or torch).
        beta: ``(10,)``.
        dtype: ``"float32"`` (the paper) or ``"float16"`` (half the bytes).

    Returns:
        ``(136,)`` little-endian array of that dtype; ``.tobytes()`` is the wire format.
    """
    theta = np.asarray(_to_numpy(theta6d), np.float32).reshape(-1)
    beta = np.asarray(_to_numpy(beta), np.float32).reshape(-1)
    if theta.size != THETA_DIM or beta.size != BETA_DIM:
        raise ValueError(f"need 126 theta6d and 10 beta values, got {theta.size} and {beta.size}")
    return np.concatenate((theta, beta)).astype(_wire_dtype(dtype))


def decode_message(message, dtype="float32") -> tuple[np.ndarray, np.ndarray]:
    """Unpack a message (array, or ``bytes`` in the given dtype) into ``theta6d (21, 6)`` and
    ``beta (10,)``, both float32."""
    if isinstance(message, (bytes, bytearray, memoryview)):
        arr = np.frombuffer(message, dtype=_wire_dtype(dtype))
    else:
        arr = np.asarray(_to_numpy(message))
    arr = arr.astype(np.float32).reshape(-1)
    if arr.size != MESSAGE_DIM:
        raise ValueError(f"a message has {MESSAGE_DIM} values, got {arr.size}")
    return arr[:THETA_DIM].reshape(NUM_BODY_JOINTS, 6).copy(), arr[THETA_DIM:].copy()


def _to_numpy(x):
    return x.detach().cpu().numpy() if isinstance(x, Tensor) else x


def fuse_message_list(messages: Sequence, dtype: torch.dtype = torch.float32) -> Tensor | None:
    """Mean of the other views' messages as a ``(1, 136)`` tensor (None if the list is empty).

    Same arithmetic as ``variants.fuse_messages`` in the batched forward (stack, then mean), so a
    two-view staged run reproduces the batched one.
    """
    if len(messages) == 0:
        return None
    rows = []
    for m in messages:
        t = torch.as_tensor(np.asarray(_to_numpy(m)).astype(np.float32)).reshape(MESSAGE_DIM)
        rows.append(t.to(dtype))
    return torch.stack(rows, dim=0).mean(dim=0, keepdim=True)


class DroneNode:
    """One view's network, run stage by stage (batch 1, inference: the model is put in eval mode).

    Args:
        model: a trained :class:`AirPoseNet` (any variant); several nodes may share one model.
        message_dtype: dtype of the messages this node emits (``"float32"`` or ``"float16"``);
            the node itself keeps full precision.
    """

    def __init__(self, model: AirPoseNet, message_dtype="float32"):
        model.eval()
        self.model = model
        self.message_dtype = _wire_dtype(message_dtype)
        self.num_stages = model.num_iterations
        self._k = 0

    @property
    def completed_stages(self) -> int:
        return self._k

    def _dtype(self) -> torch.dtype:
        return self.model.init_beta.dtype

    def _emit(self) -> np.ndarray:
        msg = self.model.message(self._state)[0]
        self._messages.append(msg)
        return msg.detach().cpu().numpy().astype(self.message_dtype)

    @torch.no_grad()
    def stage1(self, image: Tensor, P: Tensor | None = None) -> np.ndarray:
        """Backbone and the first iteration.

        Args:
            image: ``(1, 3, S, S)`` or ``(3, S, S)`` normalised crop.
            P: ``(1, 3)`` or ``(3,)`` crop vector (needed by Fullcam and AirPose).

        Returns:
            this view's message ``(136,)``.
        """
        dtype = self._dtype()
        image = torch.as_tensor(image).to(dtype)
        image = image[None] if image.dim() == 3 else image
        if image.shape[0] != 1:
            raise ValueError("a DroneNode runs one image at a time: image must be (1, 3, S, S)")
        self._P = None if P is None else torch.as_tensor(P).to(dtype).reshape(1, 3)
        self._input_size = int(image.shape[-1])
        self._feat = self.model.features(image)
        self._messages: list[Tensor] = []
        state = self.model.initial_state((1,))
        other = self.model.mean_message((1,)) if self.model.spec.multiview else None
        self._state = self.model.iterate(self._feat, self._P, state, other)
        self._k = 1
        return self._emit()

    @torch.no_grad()
    def stage(self, k: int, other_messages: Sequence = ()) -> np.ndarray:
        """Iteration k (2, 3, ...) using the other views' messages from stage k - 1.

        Args:
            k: stage number; stages must run in order.
            other_messages: the other drones' messages of the previous stage, each ``(136,)``
                (numpy, torch or :func:`encode_message` output). Ignored by Baseline and Fullcam.

        Returns:
            this view's message ``(136,)``.
        """
        if self._k == 0:
            raise RuntimeError("run stage1 first")
        if k != self._k + 1 or k > self.num_stages:
            raise ValueError(f"expected stage {self._k + 1} (of {self.num_stages}), got {k}")
        other = None
        if self.model.spec.multiview:
            other = fuse_message_list(other_messages, self._dtype())
            if other is None:
                other = self.model.mean_message((1,))
        self._state = self.model.iterate(self._feat, self._P, self._state, other)
        self._k = k
        return self._emit()

    def result(self) -> dict:
        """This view's outputs with a leading batch of 1 (the per-view slice of the batched
        forward): phi6d (1, 6), theta6d (1, 21, 6), beta (1, 10), tau (1, 3) or cam (1, 3),
        messages (list of (1, 136)) and input_size."""
        if self._k == 0:
            raise RuntimeError("no stage has run")
        out = self.model.decode(self._state)
        out["messages"] = [m[None] for m in self._messages]
        out["input_size"] = self._input_size
        return out

    @property
    def state(self) -> Tensor:
        """Packed state ``(1, 145)`` after the last stage (for checkpointing a pipeline)."""
        return self.model.pack_state(self._state)
