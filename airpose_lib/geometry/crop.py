r"""Person crop, the crop vector P and the crop <-> full-image translation of the paper (eq. 1-2).

The crop
--------
The network sees the person's bounding box ``bbox = [x0, y0, x1, y1]`` (full-image pixels),
resized keeping its aspect ratio and padded with black, centred, to ``input_size x input_size``
(224). Equivalently it sees the square of side ``L = max(w, h)`` centred on the box centre
``(ccx, ccy)``, scaled by ``s = input_size / L``. A full-image pixel ``u`` maps to the crop pixel

    u_crop = s (u - ccx) + input_size / 2        (same for v with ccy),

an affine map (:func:`crop_affine_matrix`; its top two rows are the matrix ``cv2.warpAffine``
needs, with integer pixel centres as everywhere in this package). ``warpAffine`` fills the square
with the image around the box; the paper's input is black outside the box itself, i.e. outside
the crop-pixel rectangle ``s ([x0, x1] - ccx) + input_size / 2`` (same for y). The geometry, and
everything in this module, is the same for both.

The crop vector P = [bx, by, s]
-------------------------------
``bx = ccx / cx - 1``, ``by = ccy / cy - 1`` (so ``bx cx = ccx - cx`` is the offset of the crop
centre from the principal point) and ``s = input_size / max(w, h)``.

Translation (paper eq. 1-2)
---------------------------
The network predicts the body translation ``tau_c = [x_c, y_c, z_c]`` in the "cropped and
scaled" camera; the full-frame translation ``tau = [x, y, z]`` follows from

    z = z_c s                                                    (1)
    fx x / z = (fx / s) x_c / z_c + bx cx                        (2)  (same for y with fy, by cy)

Substituting (1) into (2): ``fx x / z = fx x_c / z + bx cx``, hence
``x = x_c + bx cx z / fx`` and ``y = y_c + by cy z / fy``. Reading: in crop pixels, ``tau_c`` is
where the body origin lies for a camera with the *full-image* focal length and the principal point
at the crop centre (the crop magnifies by s, so the person looks as if at depth ``z / s``); the
lateral offset re-centres from the crop centre to the principal point.

One rule for any camera: the network's virtual camera
-----------------------------------------------------
A network learns P and the crop for the camera of its training data (``K_net``: f = 1475 px,
1920x1080). :func:`virtual_crop` forms them for any other camera ``K`` in a *virtual* camera with
the same centre and orientation and intrinsics ``K_net``: the real image mapped by
``H = K_net K^-1`` (a scale ``f_net / f`` about the principal point, moved to ``K_net``'s).
See its docstring for why the predicted translation is then the real camera's.

The image: black outside the box (one rule for every crop)
----------------------------------------------------------
Data generation renders the crop directly (:func:`crop_intrinsics`), the official loaders and the
runtime warp a full image (:func:`crop_from_image`); all of them then call :func:`pad_outside_box`,
which blacks out every crop pixel whose centre ``idx`` lies outside the box's crop-pixel
rectangle ``[u0, u1] x [v0, v1]`` (:func:`box_in_crop`): column ``idx`` is kept iff
``u0 <= idx <= u1``. So a training crop and an inference crop of the same box are the same array.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor

from .camera import split_intrinsics

__all__ = [
    "crop_vector",
    "crop_affine_matrix",
    "crop_intrinsics",
    "full_to_crop_pixels",
    "crop_to_full_pixels",
    "crop_to_full_translation",
    "full_to_crop_translation",
    "weak_perspective_to_translation",
    "translation_to_weak_perspective",
    "virtual_camera_map",
    "virtual_box",
    "virtual_crop",
    "box_in_crop",
    "pad_outside_box",
    "crop_from_image",
]


def _check_input_size(input_size: float) -> None:
    if not input_size > 0:
        raise ValueError(f"input_size must be positive, got {input_size}")


def _bbox_centre_side(bbox: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Validate ``bbox (..., 4)`` and return its centre ``ccx, ccy`` and square side ``L``, each ``(...)``."""
    if bbox.shape[-1] != 4:
        raise ValueError(f"bbox must have shape (..., 4) = [x0, y0, x1, y1], got {tuple(bbox.shape)}")
    finite = torch.isfinite(bbox).all(dim=-1)
    if not bool(finite.all()):
        bad = bbox[~finite][0].tolist()
        raise ValueError(f"bbox contains non-finite values (NaN or inf): {bad}")
    x0, y0, x1, y1 = bbox.unbind(-1)
    w, h = x1 - x0, y1 - y0
    degenerate = (w <= 0) | (h <= 0)
    if bool(degenerate.any()):
        i = degenerate.nonzero()[0].tolist()
        i = tuple(i) if i else ()
        raise ValueError(
            "empty or degenerate bbox: need x1 > x0 and y1 > y0 (width and height > 0), "
            f"got bbox {bbox[i].tolist()} with width {float(w[i])} and height {float(h[i])}"
        )
    return 0.5 * (x0 + x1), 0.5 * (y0 + y1), torch.maximum(w, h)


def _check_principal_point(cx: Tensor, cy: Tensor) -> None:
    ok = torch.isfinite(cx) & torch.isfinite(cy) & (cx != 0) & (cy != 0)
    if not bool(ok.all()):
        raise ValueError("intrinsics K must have a finite, non-zero principal point (cx, cy)")


def crop_vector(bbox: Tensor, K: Tensor, input_size: float = 224) -> Tensor:
    """The crop vector ``P = [bx, by, s]`` of the paper.

    Args:
        bbox: ``(..., 4)`` person box ``[x0, y0, x1, y1]`` in full-image pixels.
        K: ``(..., 3, 3)`` full-image intrinsics (broadcastable with bbox's batch dims).
        input_size: side of the square network input in pixels.

    Returns:
        ``(..., 3)``: ``bx = ccx / cx - 1``, ``by = ccy / cy - 1``, ``s = input_size / max(w, h)``.

    Raises:
        ValueError: on a non-finite or degenerate (``w <= 0`` or ``h <= 0``) bbox, or a zero or
            non-finite principal point.
    """
    _check_input_size(input_size)
    ccx, ccy, side = _bbox_centre_side(bbox)
    _, _, cx, cy = split_intrinsics(K)
    _check_principal_point(cx, cy)
    bx = ccx / cx - 1.0
    by = ccy / cy - 1.0
    s = input_size / side
    return torch.stack(torch.broadcast_tensors(bx, by, s), dim=-1)


def crop_affine_matrix(bbox: Tensor, input_size: float = 224) -> Tensor:
    """Homogeneous affine map from full-image pixels to crop pixels.

    ``A = [[s, 0, input_size/2 - s ccx], [0, s, input_size/2 - s ccy], [0, 0, 1]]``.
    ``A[:2]`` (as numpy) is the matrix for ``cv2.warpAffine(img, A[:2], (input_size, input_size),
    borderValue=0)``, which yields the aspect-preserving square crop; zero the pixels outside the
    box's image in the crop to get the paper's black padding (see the module docstring).

    Args:
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]``, full-image pixels.
        input_size: crop side in pixels.

    Returns:
        ``(..., 3, 3)``.
    """
    _check_input_size(input_size)
    ccx, ccy, side = _bbox_centre_side(bbox)
    s = input_size / side
    half = 0.5 * input_size
    zero, one = torch.zeros_like(s), torch.ones_like(s)
    rows = (
        torch.stack((s, zero, half - s * ccx), dim=-1),
        torch.stack((zero, s, half - s * ccy), dim=-1),
        torch.stack((zero, zero, one), dim=-1),
    )
    return torch.stack(rows, dim=-2)


def crop_intrinsics(K: Tensor, bbox: Tensor, input_size: float = 224) -> Tensor:
    """Intrinsics of the padded crop image, so that the crop can be rendered directly.

    ``K_crop = A K`` with A from :func:`crop_affine_matrix`: focal lengths ``fx s, fy s`` and
    principal point ``s (cx - ccx) + input_size / 2`` (same for y).

    Args:
        K: ``(..., 3, 3)`` full-image intrinsics.
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]``, full-image pixels.
        input_size: crop side in pixels.

    Returns:
        ``(..., 3, 3)``.
    """
    return crop_affine_matrix(bbox, input_size).to(K.dtype) @ K


def full_to_crop_pixels(uv: Tensor, bbox: Tensor, input_size: float = 224) -> Tensor:
    """Map full-image pixels to crop pixels.

    Args:
        uv: ``(..., N, 2)`` full-image pixels.
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]``.
        input_size: crop side in pixels.

    Returns:
        ``(..., N, 2)`` crop pixels ``s (uv - cc) + input_size / 2``.
    """
    _check_input_size(input_size)
    ccx, ccy, side = _bbox_centre_side(bbox)
    s = (input_size / side)[..., None, None]
    cc = torch.stack((ccx, ccy), dim=-1).unsqueeze(-2)
    return s * (uv - cc) + 0.5 * input_size


def crop_to_full_pixels(uv_crop: Tensor, bbox: Tensor, input_size: float = 224) -> Tensor:
    """Inverse of :func:`full_to_crop_pixels`.

    Args:
        uv_crop: ``(..., N, 2)`` crop pixels.
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]``.
        input_size: crop side in pixels.

    Returns:
        ``(..., N, 2)`` full-image pixels ``(uv_crop - input_size / 2) / s + cc``.
    """
    _check_input_size(input_size)
    ccx, ccy, side = _bbox_centre_side(bbox)
    s = (input_size / side)[..., None, None]
    cc = torch.stack((ccx, ccy), dim=-1).unsqueeze(-2)
    return (uv_crop - 0.5 * input_size) / s + cc


def crop_to_full_translation(tau_c: Tensor, P: Tensor, K: Tensor) -> Tensor:
    """Paper eq. (1)-(2): crop-camera translation ``tau_c`` -> full-frame camera translation ``tau``.

    ``z = z_c s`` (1) and ``fx x / z = (fx / s) x_c / z_c + bx cx`` (2); substituting (1) into
    (2) gives ``x = x_c + bx cx z / fx`` (and ``y = y_c + by cy z / fy``). See the module
    docstring for the geometric meaning.

    Args:
        tau_c: ``(..., 3)`` ``[x_c, y_c, z_c]`` (metres).
        P: ``(..., 3)`` crop vector ``[bx, by, s]`` (:func:`crop_vector`).
        K: ``(..., 3, 3)`` full-image intrinsics.

    Returns:
        ``(..., 3)`` ``tau = [x, y, z]`` in the camera frame (metres).
    """
    fx, fy, cx, cy = split_intrinsics(K)
    bx, by, s = P.unbind(-1)
    xc, yc, zc = tau_c.unbind(-1)
    z = zc * s
    x = xc + bx * cx * z / fx
    y = yc + by * cy * z / fy
    return torch.stack(torch.broadcast_tensors(x, y, z), dim=-1)


def full_to_crop_translation(tau: Tensor, P: Tensor, K: Tensor) -> Tensor:
    """Inverse of :func:`crop_to_full_translation`: ``z_c = z / s``, ``x_c = x - bx cx z / fx``.

    Args:
        tau: ``(..., 3)`` full-frame translation ``[x, y, z]``.
        P: ``(..., 3)`` crop vector ``[bx, by, s]``.
        K: ``(..., 3, 3)`` full-image intrinsics.

    Returns:
        ``(..., 3)`` ``tau_c``.
    """
    fx, fy, cx, cy = split_intrinsics(K)
    bx, by, s = P.unbind(-1)
    x, y, z = tau.unbind(-1)
    xc = x - bx * cx * z / fx
    yc = y - by * cy * z / fy
    zc = z / s
    return torch.stack(torch.broadcast_tensors(xc, yc, zc), dim=-1)


def weak_perspective_to_translation(
    cam: Tensor, P: Tensor, K: Tensor, input_size: float = 224
) -> Tensor:
    """Baseline weak-perspective crop camera ``[s_w, tx, ty]`` -> full-frame translation ``tau``.

    The weak camera maps a body point X to normalised crop coordinates
    ``s_w (X_xy + [tx, ty])`` in ``[-1, 1]`` (crop pixel = ``(1 + .) input_size / 2``). The crop
    is seen by a camera with focal ``fx s`` in crop pixels and principal point at the crop centre
    (physically consistent, CLIFF-style), so matching the scales gives the depth

        tz = 2 fx s / (input_size s_w)  (= 2 fx / (L s_w), L the box side in full pixels).

    The official code writes ``tz = 2 f / (224 s_w)``: the same formula with ``f = fx s`` the
    crop's focal length in crop pixels. ``[tx, ty, tz]`` is the translation in that crop camera,
    which shares the full camera's centre and depth; re-centring from the crop centre to the
    principal point is the eq. (1)-(2) offset: ``x = tx + bx cx tz / fx``,
    ``y = ty + by cy tz / fy``.

    With non-square pixels (fx != fy) the depth uses fx, so the weak camera's vertical scale is
    effectively ``s_w fy / fx``; with fx == fy the body origin at tau projects exactly to the
    pixel predicted by the weak camera.

    Args:
        cam: ``(..., 3)`` ``[s_w, tx, ty]``.
        P: ``(..., 3)`` crop vector ``[bx, by, s]``.
        K: ``(..., 3, 3)`` full-image intrinsics.
        input_size: crop side in pixels.

    Returns:
        ``(..., 3)`` ``tau`` in the full camera frame (metres).
    """
    _check_input_size(input_size)
    fx, fy, cx, cy = split_intrinsics(K)
    bx, by, s = P.unbind(-1)
    sw, tx, ty = cam.unbind(-1)
    tz = 2.0 * fx * s / (input_size * sw)
    x = tx + bx * cx * tz / fx
    y = ty + by * cy * tz / fy
    return torch.stack(torch.broadcast_tensors(x, y, tz), dim=-1)


def translation_to_weak_perspective(
    tau: Tensor, P: Tensor, K: Tensor, input_size: float = 224
) -> Tensor:
    """Inverse of :func:`weak_perspective_to_translation`.

    ``s_w = 2 fx s / (input_size z)``, ``tx = x - bx cx z / fx``, ``ty = y - by cy z / fy``.

    Args:
        tau: ``(..., 3)`` full-frame translation ``[x, y, z]``, ``z > 0``.
        P: ``(..., 3)`` crop vector ``[bx, by, s]``.
        K: ``(..., 3, 3)`` full-image intrinsics.
        input_size: crop side in pixels.

    Returns:
        ``(..., 3)`` ``[s_w, tx, ty]``.
    """
    _check_input_size(input_size)
    fx, fy, cx, cy = split_intrinsics(K)
    bx, by, s = P.unbind(-1)
    x, y, z = tau.unbind(-1)
    sw = 2.0 * fx * s / (input_size * z)
    tx = x - bx * cx * z / fx
    ty = y - by * cy * z / fy
    return torch.stack(torch.broadcast_tensors(sw, tx, ty), dim=-1)


def virtual_camera_map(K: Tensor, K_net: Tensor) -> Tensor:
    """Homogeneous map ``H = K_net K^-1`` from pixels of camera K to pixels of the virtual camera
    ``K_net`` with the same centre and orientation (skew ignored, as in :func:`split_intrinsics`).

    ``u' = (fx' / fx) (u - cx) + cx'`` (same for v): both cameras see the ray of ``u`` at ``u'``.

    Args:
        K: ``(..., 3, 3)`` intrinsics of the real image.
        K_net: ``(..., 3, 3)`` intrinsics of the virtual (the network's training) camera.

    Returns:
        ``(..., 3, 3)``.
    """
    fx, fy, cx, cy = split_intrinsics(K)
    gx, gy, dx, dy = split_intrinsics(K_net)
    kx, ky = gx / fx, gy / fy
    kx, ky, tx, ty = torch.broadcast_tensors(kx, ky, dx - kx * cx, dy - ky * cy)
    zero, one = torch.zeros_like(kx), torch.ones_like(kx)
    rows = (torch.stack((kx, zero, tx), dim=-1), torch.stack((zero, ky, ty), dim=-1),
            torch.stack((zero, zero, one), dim=-1))
    return torch.stack(rows, dim=-2)


def virtual_box(bbox: Tensor, K: Tensor, K_net: Tensor) -> tuple[Tensor, Tensor]:
    """The box of camera K as the virtual camera ``K_net`` sees it (:func:`virtual_camera_map`).

    Args:
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]`` in pixels of the real image.
        K: ``(..., 3, 3)`` intrinsics of the real image.
        K_net: ``(..., 3, 3)`` intrinsics of the virtual camera.

    Returns:
        ``box_v (..., 4)`` in virtual-camera pixels and ``H (..., 3, 3)``, real -> virtual pixels.
        With ``K = K_net``, ``H`` is the identity and ``box_v`` equals ``bbox`` bit for bit.
    """
    H = virtual_camera_map(K, K_net).to(bbox.dtype)
    kx, ky, tx, ty = H[..., 0, 0], H[..., 1, 1], H[..., 0, 2], H[..., 1, 2]
    x0, y0, x1, y1 = bbox.unbind(-1)
    box_v = torch.stack(torch.broadcast_tensors(kx * x0 + tx, ky * y0 + ty, kx * x1 + tx, ky * y1 + ty), dim=-1)
    return box_v, H


def virtual_crop(bbox: Tensor, K: Tensor, K_net: Tensor, input_size: float = 224) -> tuple[Tensor, Tensor]:
    """The network input of a box seen by any camera: crop map and P formed in the virtual camera.

    The box is mapped into the virtual camera ``K_net`` (:func:`virtual_camera_map`, ``H``), and
    the crop and ``P`` are those of the mapped box there: ``A = crop_affine_matrix(H bbox) H``
    (real-image pixels -> crop pixels) and ``P = crop_vector(H bbox, K_net)``.

    Why this is the right input, and why the output needs no correction: the virtual camera has
    the real camera's centre and orientation, so a point has the same camera-frame coordinates in
    both; only the pixels it lands on differ, by ``H``. A person at ``tau`` therefore gives, in
    the virtual camera, exactly the box and P that a training camera (``K_net``) would give for a
    person at ``tau``; the crop content is the same as in the real image (cropping scales the box
    to S pixels anyway, so ``H``'s scale cancels; only a non-square-pixel ``K`` is resampled
    anisotropically to square pixels). The network, trained on ``K_net``, sees a training-like
    input and predicts ``tau`` in the virtual camera's frame, which *is* the real camera's frame:
    no focal term to undo. With ``K = K_net`` this is :func:`crop_affine_matrix` and
    :func:`crop_vector` unchanged. The weak-perspective conversion must then use ``K_net`` with
    this P (:func:`weak_perspective_to_translation`); projecting the predicted body uses ``K``.

    Args:
        bbox: ``(..., 4)`` ``[x0, y0, x1, y1]`` in pixels of the real image.
        K: ``(..., 3, 3)`` intrinsics of the real image.
        K_net: ``(..., 3, 3)`` intrinsics of the camera the network was trained with.
        input_size: crop side S.

    Returns:
        ``A (..., 3, 3)`` real-image pixels -> crop pixels (``A[:2]`` for ``cv2.warpAffine``) and
        ``P (..., 3)`` ``[bx, by, s]`` in the virtual camera.
    """
    box_v, H = virtual_box(bbox, K, K_net)
    A = crop_affine_matrix(box_v, input_size) @ H
    P = crop_vector(box_v, K_net.to(bbox.dtype), input_size)
    return A, P


# -- the image: black outside the box -----------------------------------------------------------
def box_in_crop(bbox: np.ndarray, input_size: int) -> tuple[float, float, float, float]:
    """The box ``[x0, y0, x1, y1]`` (full-frame px) in crop pixels: ``(u0, v0, u1, v1)``.

    ``u = s (x - ccx) + S / 2`` with ``s = S / max(w, h)``, as :func:`full_to_crop_pixels`, in
    Python floats. This arithmetic *is* the edge rule's: the long side's first edge lands on 0
    only up to rounding, and whether pixel 0 is kept follows these exact operations (the ones
    the still-frame data were generated with), so every crop must compute the edges here.

    Args:
        bbox: ``(4,)`` the box in full-frame pixels of the camera the crop is formed in.
        input_size: crop side S.
    """
    x0, y0, x1, y1 = (float(v) for v in np.asarray(bbox).reshape(4))
    s = input_size / max(x1 - x0, y1 - y0)
    ccx, ccy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    return (s * (x0 - ccx) + input_size / 2, s * (y0 - ccy) + input_size / 2,
            s * (x1 - ccx) + input_size / 2, s * (y1 - ccy) + input_size / 2)


def pad_outside_box(image: np.ndarray, bbox: np.ndarray) -> np.ndarray:
    """Black out the crop pixels whose centre falls outside the person box (in place; returns it).

    Column ``j`` is kept iff ``u0 <= j <= u1`` and row ``i`` iff ``v0 <= i <= v1``, with the
    edges from :func:`box_in_crop`: the one rule of every crop in the kit.

    Args:
        image: ``(S, S, C)`` crop of ``bbox`` (any dtype).
        bbox: ``(4,)`` the box in full-frame pixels of the camera the crop is formed in.
    """
    S = image.shape[0]
    u0, v0, u1, v1 = box_in_crop(bbox, S)
    idx = np.arange(S)
    image[:, (idx < u0) | (idx > u1)] = 0
    image[(idx < v0) | (idx > v1)] = 0
    return image


def crop_from_image(image: np.ndarray, M: np.ndarray, bbox: np.ndarray, input_size: int) -> np.ndarray:
    """The network input of a box cut from an image: warped by ``M``, black outside the box.

    Args:
        image: ``(H, W, C)`` uint8.
        M: ``(3, 3)`` or ``(2, 3)`` map from ``image``'s pixels to crop pixels (e.g.
            :func:`crop_affine_matrix`, or :func:`virtual_crop`'s ``A``).
        bbox: ``(4,)`` the box in the pixels of the camera the crop is formed in (the real
            camera for :func:`crop_affine_matrix`, :func:`virtual_box`'s for a virtual crop).
        input_size: crop side S.

    Returns:
        ``(S, S, C)`` uint8: bilinear ``cv2.warpAffine`` (black beyond the image), then
        :func:`pad_outside_box`.
    """
    out = cv2.warpAffine(image, np.asarray(M, np.float64)[:2], (input_size, input_size), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return pad_outside_box(out, bbox)
