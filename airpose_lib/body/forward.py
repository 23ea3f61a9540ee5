r"""The body model evaluated in the paper's root convention, for the whole kit.

    V = phi V0(theta, beta) + tau        (the same for the joints)

``V0`` is SMPL-X with the 21 body rotations theta, identity root, zero translation and every
other joint (jaw, eyes, fingers) at the model's rest rotation (``pose_mean``; identity for the
flat-hand models the kit loads); phi and tau then act about the model origin, unlike smplx's
``global_orient``/``transl`` (about the pelvis). Training losses, fitting, data generation and
evaluation all go through :class:`BodyForward`; it is smplx's linear blend skinning (``lbs``)
restricted to what the caller asks for:

* ``joints``: indices into the 76 outputs of smplx (55 skeleton joints, then the 21 keypoint
  vertices: nose, eyes, ears, toes, heels, fingertips); ``vertices``: all mesh vertices, a fixed
  subset (the loss's vertex subsampling) or none (joints only, fitting);
* the kinematic chain runs over the joints the outputs need (and their ancestors) only, kept as a
  list of per-joint tensors: indexing one stacked tensor per parent, as smplx's
  ``batch_rigid_transform`` does, makes the backward pass write a full-size zero gradient per
  joint (~4x slower than the forward for a 1,000-frame fit);
* a joint at a constant identity rotation moves its vertices exactly like its parent does, so
  its skinning weights are folded onto the nearest ancestor that rotates (flat hands: the mesh is
  skinned by the 22 body joints, not 55);
* a shared ``beta`` (one per sequence) gives the rest joints once, broadcast over the frames;
  all-zero pose correctives (the open model) are skipped.
"""
from __future__ import annotations

import weakref
from collections.abc import Sequence

import numpy as np
import torch
from smplx.lbs import batch_rodrigues
from torch import Tensor, nn

from .joint_sets import NUM_BODY_JOINTS, NUM_OUTPUT_JOINTS, NUM_POSE_JOINTS

__all__ = ["BodyForward", "NUM_SKELETON_JOINTS", "axis_angle_rotations", "cached_body", "rest_body"]

#: Skeleton joints of SMPL-X (root, 21 body joints, jaw, 2 eyes, 2 x 15 finger joints).
NUM_SKELETON_JOINTS = 55
_THETA = range(1, NUM_BODY_JOINTS)  # the joints theta rotates


def axis_angle_rotations(theta: Tensor) -> Tensor:
    """``(..., 21, 3)`` (or ``(..., 63)``) axis-angle body pose -> ``(..., 21, 3, 3)`` matrices.

    smplx's own Rodrigues formula, so an axis-angle pose gives the rotations smplx's forward uses.
    """
    lead = theta.shape[:-2] if theta.shape[-1] == 3 else theta.shape[:-1]
    return batch_rodrigues(theta.reshape(-1, 3)).reshape(*lead, NUM_POSE_JOINTS, 3, 3)


def _fold_targets(parents: list[int], rest_aa: Tensor) -> list[int]:
    """Per skeleton joint, the joint whose skinning transform it shares: itself, or for a joint
    at a constant identity rotation (not root, not theta's) that of its parent, recursively."""
    target: list[int] = []
    for j, p in enumerate(parents):
        constant_identity = j >= NUM_BODY_JOINTS and bool((rest_aa[j] == 0).all())
        target.append(target[p] if constant_identity else j)
    return target


class BodyForward(nn.Module):
    """Selected joints and vertices of ``V = phi V0(theta, beta) + tau`` from rotation matrices.

    Args:
        model: a loaded ``smplx.SMPLX`` (open or licensed); its buffers are copied (or viewed),
            so later changes to ``model`` do not reach this module.
        joints: indices into the 76 smplx outputs (55 skeleton joints, 21 keypoint vertices);
            default the 22 body joints.
        vertices: ``"all"`` (the mesh), ``(N,)`` vertex indices (a fixed subset), or None.
    """

    def __init__(self, model, joints: Sequence[int] = range(NUM_BODY_JOINTS),
                 vertices: str | Tensor | Sequence[int] | None = "all") -> None:
        super().__init__()
        out_idx = [int(i) for i in joints]
        n_kp = model.vertex_joint_selector.extra_joints_idxs.numel()
        n_out = NUM_SKELETON_JOINTS + n_kp
        if not out_idx or min(out_idx) < 0 or max(out_idx) >= n_out:
            raise ValueError(f"joints must be non-empty indices in [0, {n_out}), got {out_idx}")
        dtype, device = model.v_template.dtype, model.v_template.device
        parents = model.parents.tolist()
        rest_aa = model.pose_mean.reshape(NUM_SKELETON_JOINTS, 3)
        fold = _fold_targets(parents, rest_aa)
        # Skinning weights onto the joints whose transforms differ: (V, 55), folded columns zero.
        W = torch.zeros_like(model.lbs_weights).index_add_(
            1, torch.tensor(fold, device=device), model.lbs_weights)

        kp_sel = sorted({i - NUM_SKELETON_JOINTS for i in out_idx if i >= NUM_SKELETON_JOINTS})
        kp_ids = model.vertex_joint_selector.extra_joints_idxs[kp_sel].to(device)
        nv = model.v_template.shape[0]
        if vertices is None:
            mesh_ids = None
        elif isinstance(vertices, str):
            if vertices != "all":
                raise ValueError(f"vertices must be 'all', indices or None, got {vertices!r}")
            mesh_ids = slice(None)
        else:
            mesh_ids = torch.as_tensor(vertices, device=device).long()

        # The chain: root, theta's joints, requested skeleton joints, skinning joints, ancestors.
        need = {0, *_THETA} | {i for i in out_idx if i < NUM_SKELETON_JOINTS}
        skin_cols = W[kp_ids] if mesh_ids is None else torch.cat([W[kp_ids], W[mesh_ids]])
        skin = sorted((skin_cols.abs() > 0).any(0).nonzero().flatten().tolist())
        need |= set(skin)
        for j in list(need):
            while parents[j] >= 0:
                j = parents[j]
                need.add(j)
        chain = sorted(need)  # SMPL-X parents precede their children: sorted order is a valid chain
        local = {g: i for i, g in enumerate(chain)}
        self.chain = tuple(chain)
        self.local_parent = tuple(local[parents[g]] if parents[g] >= 0 else -1 for g in chain)
        self._theta_local = tuple(local[g] for g in _THETA)
        skin = skin or [0]  # nothing skinned (no vertices asked for): keep one harmless column
        self._skin_local = tuple(local[g] for g in skin)
        # Where each requested output comes from, in cat([chain joints, keypoint vertices]).
        self.register_buffer("_gather", torch.tensor(
            [local[i] if i < NUM_SKELETON_JOINTS else len(chain) + kp_sel.index(i - NUM_SKELETON_JOINTS)
             for i in out_idx], device=device), persistent=False)
        self.num_betas = model.num_betas

        # Buffers are the body model's data, not trained state: not persistent.
        buf = lambda name, value: self.register_buffer(name, value, persistent=False)  # noqa: E731
        chain_t = torch.tensor(chain, device=device)
        reg = model.J_regressor[chain_t]  # (n, V)
        shapedirs = model.shapedirs[..., : self.num_betas]  # (V, 3, S)
        buf("J_template", reg @ model.v_template)  # (n, 3)
        buf("J_dirs", torch.einsum("jv,vcs->jcs", reg, shapedirs))  # (n, 3, S)
        rest = batch_rodrigues(rest_aa.reshape(-1, 3)).reshape(NUM_SKELETON_JOINTS, 3, 3)
        rest[rest_aa.abs().sum(-1) == 0] = torch.eye(3, dtype=dtype, device=device)  # exact identity
        buf("rest_rot", rest[chain_t].clone())  # (n, 3, 3); theta's rows are replaced per call
        # Pose correctives: theta's 21 x 9 rows vary; the other joints' rest rotations are constant.
        n_pd = model.posedirs.shape[0]
        posedirs = model.posedirs.reshape(n_pd, nv, 3)  # (54 x 9, V, 3)
        feat = (rest[1:] - torch.eye(3, dtype=dtype, device=device)).reshape(-1)
        feat[: NUM_POSE_JOINTS * 9] = 0.0
        self._has_posedirs = bool(model.posedirs[: NUM_POSE_JOINTS * 9].abs().max() > 0)
        self._num_kp = len(kp_sel)
        self._has_mesh = mesh_ids is not None
        for prefix, ids in (("kp", kp_ids), ("mesh", mesh_ids)):
            if ids is None:
                continue
            full = isinstance(ids, slice)  # views, not copies, of the large arrays
            buf(f"{prefix}_template", model.v_template if full else model.v_template[ids])  # (N, 3)
            buf(f"{prefix}_dirs", shapedirs if full else shapedirs[ids])  # (N, 3, S)
            pd = model.posedirs[: NUM_POSE_JOINTS * 9] if full else \
                posedirs[: NUM_POSE_JOINTS * 9, ids].reshape(NUM_POSE_JOINTS * 9, -1)
            buf(f"{prefix}_posedirs", pd)  # (189, 3N)
            buf(f"{prefix}_pose_const", torch.einsum("f,fvc->vc", feat, posedirs[:, ids]))  # (N, 3)
            buf(f"{prefix}_weights", W[ids][:, skin].contiguous())  # (N, s)
        self._has_pose_const = bool(feat.abs().max() > 0)  # a rest pose that is not flat

    @property
    def num_joints(self) -> int:
        """Number of joint outputs (``len(joints)``)."""
        return self._gather.numel()

    @property
    def num_vertices(self) -> int:
        """Number of mesh vertices evaluated (0 without a mesh)."""
        return self.mesh_template.shape[0] if self._has_mesh else 0

    def _chain(self, theta: Tensor, J_rest: Tensor) -> tuple[Tensor, Tensor]:
        """Global rotations ``(B, n, 3, 3)`` and positions ``(B, n, 3)`` of the chain's joints."""
        B = theta.shape[0]
        rot = list(self.rest_rot.unbind(0))
        for k, li in enumerate(self._theta_local):
            rot[li] = theta[:, k]
        J = J_rest.unbind(1)
        G_R: list[Tensor | None] = []
        G_t: list[Tensor] = []
        for i, p in enumerate(self.local_parent):
            if p < 0:  # root: identity rotation at its rest position
                G_R.append(None)
                G_t.append(J[0])
                continue
            offset = J[i] - J[p]  # (b, 3)
            Rp = G_R[p]
            if Rp is None:
                G_R.append(rot[i])
                G_t.append(offset + G_t[p])
            else:
                G_R.append(Rp @ rot[i])
                G_t.append((Rp @ offset.unsqueeze(-1)).squeeze(-1) + G_t[p])
        eye = torch.eye(3, dtype=theta.dtype, device=theta.device).expand(B, 3, 3)
        R_all = torch.stack([eye if r is None else r.expand(B, 3, 3) for r in G_R], 1)
        t_all = torch.stack([t.expand(B, 3) for t in G_t], 1)
        return R_all, t_all

    def _skin(self, prefix: str, theta: Tensor, shape: Tensor, A: Tensor) -> Tensor:
        """Posed points ``(B, N, 3)`` of the ``kp`` or ``mesh`` set: rest shape, pose correctives,
        then ``sum_j w_j A_j``."""
        B = theta.shape[0]
        dirs = getattr(self, f"{prefix}_dirs")[..., : shape.shape[-1]]
        p = getattr(self, f"{prefix}_template") + torch.einsum("vcs,bs->bvc", dirs, shape)
        if self._has_pose_const:
            p = p + getattr(self, f"{prefix}_pose_const")
        if self._has_posedirs:
            eye = torch.eye(3, dtype=theta.dtype, device=theta.device)
            p = p + ((theta - eye).reshape(B, -1) @ getattr(self, f"{prefix}_posedirs")).reshape(B, -1, 3)
        T = (getattr(self, f"{prefix}_weights") @ A.reshape(B, A.shape[1], 12)).reshape(B, -1, 3, 4)
        # T p by columns: elementwise products are ~5x faster than a batch of 3 x 3 matmuls
        return T[..., 0] * p[..., 0:1] + T[..., 1] * p[..., 1:2] + T[..., 2] * p[..., 2:3] + T[..., 3]

    def forward(self, theta: Tensor, beta: Tensor, phi: Tensor | None = None, tau: Tensor | None = None,
                vertices: bool = True) -> tuple[Tensor, Tensor | None]:
        """Joints and vertices of ``phi V0(theta, beta) + tau``.

        Args:
            theta: ``(..., 21, 3, 3)`` body rotations relative to the parents.
            beta: ``(..., S)`` with ``S <= num_betas`` (broadcast over theta's leading dims; one
                shared beta, ``(S,)`` or ``(1, S)``, is evaluated once).
            phi: ``(..., 3, 3)`` root rotation, or None (identity).
            tau: ``(..., 3)`` translation of the model origin, or None (zero).
            vertices: also return the mesh vertices (if the module has any).
        Returns:
            ``joints (..., len(joints), 3)`` and ``vertices (..., N, 3)`` (None unless asked for
            and built with vertices).
        """
        lead = torch.broadcast_shapes(theta.shape[:-3], beta.shape[:-1])
        theta = theta.expand(*lead, NUM_POSE_JOINTS, 3, 3).reshape(-1, NUM_POSE_JOINTS, 3, 3)
        shared = beta.shape[:-1].numel() == 1
        beta = beta.reshape(1, -1) if shared else beta.expand(*lead, beta.shape[-1]).reshape(-1, beta.shape[-1])
        S = beta.shape[-1]
        if S > self.num_betas:
            raise ValueError(f"beta has {S} entries, the body model {self.num_betas}")
        J_rest = self.J_template + torch.einsum("jcs,bs->bjc", self.J_dirs[..., :S], beta)  # (b, n, 3)
        R_all, t_all = self._chain(theta, J_rest)
        need_mesh = vertices and self._has_mesh
        points = [t_all]
        verts = None
        if self._num_kp or need_mesh:
            skin = list(self._skin_local)
            R_s = R_all[:, skin]
            t_s = t_all[:, skin] - (R_s @ J_rest[:, skin].unsqueeze(-1)).squeeze(-1)
            A = torch.cat((R_s, t_s.unsqueeze(-1)), -1)  # (B, s, 3, 4) skinning transforms
            if self._num_kp:
                points.append(self._skin("kp", theta, beta, A))
            if need_mesh:
                verts = self._skin("mesh", theta, beta, A).reshape(*lead, -1, 3)
        joints = torch.cat(points, 1)[:, self._gather].reshape(*lead, -1, 3)
        if phi is not None:
            joints = joints @ phi.transpose(-1, -2)
            verts = verts @ phi.transpose(-1, -2) if verts is not None else None
        if tau is not None:
            joints = joints + tau.unsqueeze(-2)
            verts = verts + tau.unsqueeze(-2) if verts is not None else None
        return joints, verts


# One BodyForward per (body model, outputs): building one regresses the joints from the mesh.
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def cached_body(model, mesh: bool = True) -> BodyForward:
    """The 76-output :class:`BodyForward` of ``model`` (with the full mesh if ``mesh``), built once
    per model and rebuilt if the model's dtype or device changed."""
    per_model = _CACHE.setdefault(model, {})
    body = per_model.get(mesh)
    ref = model.v_template
    if body is None or body.J_template.dtype != ref.dtype or body.J_template.device != ref.device:
        body = BodyForward(model, range(NUM_OUTPUT_JOINTS), "all" if mesh else None)
        per_model[mesh] = body
    return body


def rest_body(model, betas: np.ndarray, theta: np.ndarray, mesh: bool = True
              ) -> tuple[np.ndarray | None, np.ndarray]:
    """``V0``: vertices and 76 joints of the body with identity root and zero translation.

    A numpy adapter of :class:`BodyForward` for the data generators (no gradients; computed in
    the model's dtype, returned as float64).

    Args:
        model: ``smplx.SMPLX``. betas: ``(B, S)``. theta: ``(B, 21, 3)`` or ``(B, 63)`` axis-angle.
        mesh: also return the vertices.
    Returns:
        ``vertices (B, V, 3)`` (None unless ``mesh``) and ``joints (B, 76, 3)``.
    """
    body = cached_body(model, mesh)
    dt = body.J_template.dtype
    with torch.no_grad():
        theta_r = axis_angle_rotations(torch.as_tensor(np.asarray(theta), dtype=dt).reshape(len(theta), -1))
        j, v = body(theta_r, torch.as_tensor(np.array(betas), dtype=dt), vertices=mesh)
    return (v.double().numpy() if v is not None else None), j.double().numpy()
