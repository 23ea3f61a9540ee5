"""The tables and figure inputs that notebooks 03, 04 and 05 show of a recording experiment
(:class:`~airpose_lib.experiments.recordings.RecordingExperiment`, which
:mod:`airpose_lib.experiments.recordings` runs and caches): depth per method, AirPose+'s checks,
the fine-tuning and selection logs, transfer to the test persons, the method comparisons, the
paper's claims, mesh overlays, and a Markdown writer for the notebooks' reports.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from airpose_lib.body import load_body_model
from airpose_lib.data.sequences.markers import relative_camera_from_markers
from airpose_lib.eval.recordings import (
    compare_methods,
    paper_claims,
    recording_frame_table,
    relative_camera_errors_against,
    relative_camera_positions,
)
from airpose_lib.eval.significance import paired_bootstrap

from .recordings import RecordingExperiment, body_vertices, scored_frames

__all__ = ["depth_summary", "overlay_inputs", "airpose_plus_checks", "finetune_table", "selection_table",
           "transfer_table", "COMPARISONS", "comparisons_table", "GAP_METHODS", "field_gap_table",
           "RECOVERY_NETWORKS", "RECOVERY_SHARE", "recovery_table", "MARKER_METHODS",
           "MARKERS_LABEL", "uav2_in_uav1", "marker_table", "claims_table",
           "markdown_table"]


def depth_summary(exp: RecordingExperiment, methods: dict[str, str]) -> pd.DataFrame:
    """Depth (z of the person in each camera frame) per person, method and UAV.

    Args:
        exp: the experiment.
        methods: label -> estimate name (e.g. ``{"SPIN-style": "Baseline (pre-trained)"}``).

    Returns:
        columns ``sequence, method, view, z_mean_m, z_err_m`` (mean |z error|, NaN without ground
        truth), ``z_err_std_m`` and ``dz_per_frame_m`` (mean |z_t - z_{t-1}|: the smoothness the
        paper's figure shows), and ``dz_per_frame_gt_m``.
    """
    rows = []
    for person in exp.persons:
        gt = exp.sequences[person].ground_truth
        for label, name in methods.items():
            z = exp.estimates[person][name]["tau"][..., 2]  # (F, V)
            for v in range(z.shape[1]):
                row = {"sequence": person, "method": label, "view": f"UAV{v + 1}",
                       "z_mean_m": float(z[:, v].mean()),
                       "dz_per_frame_m": float(np.abs(np.diff(z[:, v])).mean())}
                if gt is not None:
                    zg = gt["tau"][:, v, 2]
                    row.update(z_err_m=float(np.abs(z[:, v] - zg).mean()),
                               z_err_std_m=float(np.std(z[:, v] - zg)),
                               dz_per_frame_gt_m=float(np.abs(np.diff(zg)).mean()))
                rows.append(row)
    return pd.DataFrame(rows)


def overlay_inputs(exp: RecordingExperiment, person: str, methods, n_frames: int = 3):
    """Frames, camera-frame vertices and zoom points for :func:`airpose_lib.viz.trajectories.plot_mesh_overlays`.

    Frames are spread evenly over the recording (first and last excluded).

    Returns:
        ``images (n, V, H, W, 3)``, ``vertices {method: (n, V, N, 3)}``, ``faces (M, 3)``,
        ``K (V, 3, 3)``, frame labels, ``zoom (n, V, J, 2)`` (the detections' confident joints).
    """
    seq = exp.sequences[person]
    F, V = seq.num_frames, seq.num_views
    idx = np.linspace(0, F - 1, n_frames + 2).round().astype(int)[1:-1]
    images = np.stack([np.stack([seq.image(int(i), v) for v in range(V)]) for i in idx])
    body = load_body_model("open", "neutral")
    vertices = {m: np.stack([body_vertices(exp.estimates[person][m], body, idx, v) for v in range(V)], axis=1)
                for m in methods}
    kp = seq.keypoints["openpose"][idx].copy()  # (n, V, 25, 3)
    zoom = np.where(kp[..., 2:3] > 0.2, kp[..., :2], np.nan)
    for i in range(len(idx)):  # no confident joint: zoom on the first method's projected mesh
        for v in range(V):
            if np.all(np.isnan(zoom[i, v])):
                vv = vertices[methods[0]][i, v]
                uv = (vv @ seq.K[v].T)[:, :2] / vv[:, 2:3]
                zoom[i, v, :2] = [uv.min(0), uv.max(0)]
    labels = [f"frame {int(seq.frames[i])}" for i in idx]
    return images, vertices, np.asarray(body.faces, dtype=np.int64), seq.K, labels, zoom


def airpose_plus_checks(table: pd.DataFrame, person: str | None = None) -> pd.DataFrame:
    """The paper's expectations about AirPose+, as measured (one row per claim and person).

    AirPose+ vs AirPose: lower MPJPE, lower relative-camera translation and rotation errors, lower
    jitter; fine-tuning: lower MPJPE than the pre-trained network on the test person.
    """
    rows = []
    persons = [person] if person else list(table["sequence"].unique())
    claims = [("AirPose+ MPJPE < AirPose", "AirPose+", "AirPose", "mpjpe_m"),
              ("AirPose+ relative-camera translation error < AirPose", "AirPose+", "AirPose", "rel_t_err_m"),
              ("AirPose+ relative-camera rotation error < AirPose", "AirPose+", "AirPose", "rel_rot_deg"),
              ("AirPose+ jitter < AirPose", "AirPose+", "AirPose", "jitter_mps2"),
              ("fine-tuned AirPose MPJPE < pre-trained", "AirPose", "AirPose (pre-trained)", "mpjpe_m"),
              ("fine-tuned Baseline MPJPE < pre-trained", "Baseline", "Baseline (pre-trained)", "mpjpe_m"),
              ("AirPose position error < Baseline (UAV1)", "AirPose", "Baseline", "mpe_uav1_m")]
    for p in persons:
        t = table[table["sequence"] == p].set_index("method")
        for claim, a, b, col in claims:
            if a in t.index and b in t.index and col in t:
                va, vb = float(t.loc[a, col]), float(t.loc[b, col])
                rows.append({"sequence": p, "claim": claim, "value": va, "reference": vb,
                             "holds": bool(va < vb)})
    out = pd.DataFrame(rows)
    return out[["sequence", "claim", "value", "reference", "holds"]] if not out.empty else out


def finetune_table(exp: RecordingExperiment) -> pd.DataFrame:
    """One row per fine-tuned network: steps, the selection rule, the selected step and its
    held-out 2D loss, where a loss term first started overfitting (and which), the per-view
    agreement threshold and how many OpenPose keypoints the two-detector filter kept or dropped
    (and why)."""
    rows = []
    for label, info in exp.finetune_info.items():
        k = info.get("keypoints") or {}
        seen = sum(k.get(x, 0) for x in ("kept", "disagree", "unconfirmed", "low_confidence"))
        rows.append({"network": label, "targets": info.get("targets", "detections"), "steps": info.get("steps"),
                     "selection_rule": info.get("selection_rule"),
                     "selected_step": info.get("selected_step"), "overfit_step": info.get("overfit_step"),
                     "overfit_terms": ", ".join(info.get("overfit_terms") or []),
                     "heldout_j2d": info.get("heldout_j2d"), "train_frames": info.get("frames"),
                     "heldout_frames": info.get("heldout_frames"),
                     "threshold_px": ", ".join(f"{t:.0f}" for t in info.get("threshold_px") or []),
                     "kept": k.get("kept"), "dropped_disagree": k.get("disagree"),
                     "dropped_unconfirmed": k.get("unconfirmed"), "dropped_low_conf": k.get("low_confidence"),
                     "missing": k.get("missing"),
                     "dropped_share": (seen - k.get("kept", 0)) / seen if seen else float("nan")})
    return pd.DataFrame(rows)


def selection_table(exp: RecordingExperiment) -> pd.DataFrame:
    """The model-selection log of every fine-tuned network (long format): per checkpoint step the
    loss terms on person 1's held-out and training frames (the only inputs of the choice) and the
    test persons' errors (``diag_*``, diagnostics)."""
    parts = []
    for label, info in exp.finetune_info.items():
        sel = info.get("selection") or {}
        if sel:
            parts.append(pd.DataFrame(sel).assign(network=label))
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def transfer_table(exp: RecordingExperiment) -> pd.DataFrame:
    """Does fine-tuning on the tuning person help the test persons? From the selection logs.

    One row per fine-tuned network and test person: the 2D targets it was tuned on, the tuning
    person's held-out 2D loss before tuning and at its best later checkpoint (fitting works), and
    the test person's MPJPE and 2D error (diagnostics, px at 1920 wide) before tuning, at the kept
    checkpoint and over all later checkpoints (min, max). ``helps_test`` is True when some later
    checkpoint has a lower test MPJPE than the network before tuning.
    """
    rows = []
    for label, info in exp.finetune_info.items():
        sel = pd.DataFrame(info.get("selection") or {})
        if sel.empty or "step" not in sel:
            continue
        first, later = sel[sel["step"] == sel["step"].min()].iloc[0], sel[sel["step"] > sel["step"].min()]
        kept = sel[sel["step"] == info.get("selected_step")]
        tests = sorted({c[len("diag_"):-len("_mpjpe_m")] for c in sel
                        if c.startswith("diag_") and c.endswith("_mpjpe_m")})
        for test in tests:
            mp, px = f"diag_{test}_mpjpe_m", f"diag_{test}_j2d_px"
            rows.append({"network": label, "targets": info.get("targets", "detections"), "test": test,
                         "tuning_heldout_j2d_before": first["heldout_j2d"],
                         "tuning_heldout_j2d_best_later": later["heldout_j2d"].min() if len(later) else np.nan,
                         "test_mpjpe_before_m": first[mp],
                         "test_mpjpe_kept_m": kept[mp].iloc[0] if len(kept) else np.nan,
                         "test_mpjpe_later_min_m": later[mp].min() if len(later) else np.nan,
                         "test_mpjpe_later_max_m": later[mp].max() if len(later) else np.nan,
                         "test_j2d_px_before": first[px] if px in sel else np.nan,
                         "test_j2d_px_later_min": later[px].min() if px in sel and len(later) else np.nan,
                         "helps_test": bool(len(later) and later[mp].min() < first[mp])})
    return pd.DataFrame(rows)


def _block_frames(sequence, block_s: float) -> int:
    """Frames in ``block_s`` seconds of a recording with ground truth (its ``fps``, default 30),
    at least 1: the block length of the recordings' block bootstraps."""
    return max(1, round(block_s * float(sequence.ground_truth.get("fps", 30.0))))


#: The method comparisons of :func:`comparisons_table` (method, reference): what fine-tuning on
#: person 1 changes for each network, and what AirPose+ adds to AirPose.
COMPARISONS = (("AirPose", "AirPose (pre-trained)"), ("Baseline", "Baseline (pre-trained)"), ("AirPose+", "AirPose"))


def comparisons_table(exp: RecordingExperiment, pairs=COMPARISONS, block_s: float = 1.0) -> pd.DataFrame:
    """:func:`airpose_lib.eval.recordings.compare_methods` on every recording with ground truth,
    over the frames every network estimated (as the error table), blocks of ``block_s`` seconds.

    Returns:
        the comparison rows with a ``sequence`` column first (empty without ground truth).
    """
    parts = []
    for person in exp.persons:
        seq, est = exp.sequences[person], exp.estimates[person]
        if seq.ground_truth is None:
            continue
        keep = np.flatnonzero(scored_frames(est))
        methods = [m for m in dict.fromkeys(x for pair in pairs for x in pair) if m in est]
        frames = {}
        for m in methods:
            t = recording_frame_table(est[m], seq.ground_truth, exp.joints[person][m], m)
            frames[m] = t[t["frame"].isin(keep)]
        usable = [(a, b) for a, b in pairs if a in frames and b in frames]
        part = compare_methods(frames, usable, block=_block_frames(seq, block_s))
        parts.append(part.assign(sequence=person)[["sequence", *part.columns]])
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


#: The networks whose field-against-clean gap :func:`field_gap_table` measures: before any
#: fine-tuning (the domain gap itself), after fine-tuning on the tuning person, and AirPose+.
GAP_METHODS = ("Baseline (pre-trained)", "AirPose (pre-trained)", "Baseline", "AirPose", "AirPose+")


def _field_and_clean_frames(clean: RecordingExperiment, field: RecordingExperiment):
    """``(person, frames)`` for each field recording with ground truth and a clean twin: the
    frames both experiments scored (``(n,)`` frame positions)."""
    for person in field.persons:
        if person in clean.persons and field.sequences[person].ground_truth is not None:
            yield person, np.intersect1d(np.flatnonzero(scored_frames(clean.estimates[person])),
                                         np.flatnonzero(scored_frames(field.estimates[person])))


def field_gap_table(clean: RecordingExperiment, field: RecordingExperiment, methods=GAP_METHODS,
                    block_s: float = 1.0) -> pd.DataFrame:
    """Each method's error on the field recordings against the clean ones, frame by frame.

    A field recording is its clean one with other pixels (the same motion, flights, seeds and
    ground truth: ``sequences: field_recordings:``), so the two are compared like two methods on
    one recording: :func:`airpose_lib.eval.recordings.compare_methods` with A = the method on the
    field frames, B = the same method on the clean frames, over the frames both experiments
    scored, blocks of ``block_s`` seconds. A positive ``difference`` is what the field's pixels
    cost; for the fine-tuned rows each experiment fine-tuned on its own tuning recording.

    Returns:
        ``sequence``, then :func:`compare_methods`'s columns (``method`` "AirPose [field]",
        ``reference`` "AirPose [clean]", ...); empty when no recording has ground truth.
    """
    parts = []
    for person, keep in _field_and_clean_frames(clean, field):
        frames, pairs = {}, []
        for m in methods:
            if m not in clean.estimates[person] or m not in field.estimates[person]:
                continue
            for tag, exp in (("field", field), ("clean", clean)):
                t = recording_frame_table(exp.estimates[person][m], exp.sequences[person].ground_truth,
                                          exp.joints[person][m], m)
                frames[f"{m} [{tag}]"] = t[t["frame"].isin(keep)]
            pairs.append((f"{m} [field]", f"{m} [clean]"))
        part = compare_methods(frames, pairs, block=_block_frames(field.sequences[person], block_s))
        parts.append(part.assign(sequence=person)[["sequence", *part.columns]])
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def _frame_errors(exp: RecordingExperiment, person: str, method: str, keep: np.ndarray, metric: str) -> pd.Series:
    """frame -> ``metric`` of ``method`` on ``person``'s recording, the mean over the views, on the
    frames ``keep``."""
    t = recording_frame_table(exp.estimates[person][method], exp.sequences[person].ground_truth,
                              exp.joints[person][method], method)
    return t[t["frame"].isin(keep)].groupby("frame")[metric].mean()


#: The networks whose recovery :func:`recovery_table` measures: (fine-tuned, pre-trained).
RECOVERY_NETWORKS = (("Baseline", "Baseline (pre-trained)"), ("AirPose", "AirPose (pre-trained)"))
#: The share of the field rise that fine-tuning must recover to count (the positive control's target).
RECOVERY_SHARE = 1 / 3


def recovery_table(clean: RecordingExperiment, field: RecordingExperiment, networks=RECOVERY_NETWORKS,
                   metric: str = "mpjpe_m", block_s: float = 1.0, n_resamples: int = 2000,
                   seed: int = 0, frames: dict[str, np.ndarray] | None = None) -> pd.DataFrame:
    """How much of the field recordings' rise does fine-tuning on the field tuning person take back?

    Per frame of a recording (the mean over its views), with ``e`` the error ``metric``:
    ``rise = e(pre-trained, field) - e(pre-trained, clean)``, what the field's pixels cost the
    network before tuning, and ``recovered = e(pre-trained, field) - e(fine-tuned, field)``, what
    fine-tuning on the field person 1 takes back. The table gives both means with 95 %
    block-bootstrap intervals (blocks of ``block_s`` seconds, as :func:`field_gap_table`) and the
    recovered share ``mean(recovered) / mean(rise)``, its interval from the same resamples (so the
    two means stay paired: :func:`~airpose_lib.eval.significance.paired_bootstrap` with ``base``).
    Over the frames both experiments scored; ``frames`` (person -> ``(n,)`` frame positions)
    restricts a recording to some of them, e.g. those a fine-tuning on that person never saw.

    ``verdict``: ``no significant rise`` (the rise's interval reaches zero: nothing to take back,
    and the share columns are NaN), else ``recovers a third or more`` (share >=
    :data:`RECOVERY_SHARE` and the recovered interval above zero: the target),
    ``recovers less than a third``, ``makes it worse`` (recovered interval below zero) or ``not
    significant``. Rows of the tuning person measure fitting, not transfer (``tuning``).

    Returns:
        ``sequence``, ``tuning``, ``network``, ``metric``, ``clean_pre``, ``field_pre``,
        ``field_tuned`` (means), ``rise``, ``rise_low``, ``rise_high``, ``recovered``,
        ``recovered_low``, ``recovered_high``, ``share``, ``share_low``, ``share_high``,
        ``frames``, ``verdict``; empty when no network was fine-tuned or nothing has ground truth.
    """
    rows = []
    for person, keep in _field_and_clean_frames(clean, field):
        if frames is not None:
            if person not in frames:
                continue
            keep = np.intersect1d(keep, np.asarray(frames[person]))
        tuning = not any(c.startswith(f"diag_{person}_") for info in field.finetune_info.values()
                         for c in (info.get("selection") or {}))
        block = _block_frames(field.sequences[person], block_s)
        for tuned, pre in networks:
            if not all(m in e.estimates[person] for m in (tuned, pre) for e in (clean, field)):
                continue
            e = pd.concat({"clean": _frame_errors(clean, person, pre, keep, metric),
                           "field": _frame_errors(field, person, pre, keep, metric),
                           "tuned": _frame_errors(field, person, tuned, keep, metric)}, axis=1).dropna().sort_index()
            if e.empty:
                continue
            rise, recovered = (e["field"] - e["clean"]).to_numpy(), (e["field"] - e["tuned"]).to_numpy()
            r_rise = paired_bootstrap(rise, n_resamples, seed=seed, block=block)
            gap = r_rise.low > 0  # without a gap to close, a share of it is not a number to read (NaN)
            r_rec = paired_bootstrap(recovered, n_resamples, seed=seed, block=block, base=rise if gap else None)
            share, share_low, share_high = r_rec.relative, r_rec.relative_low, r_rec.relative_high
            if not gap:
                verdict = "no significant rise"
            elif r_rec.low > 0:
                verdict = "recovers a third or more" if share >= RECOVERY_SHARE else "recovers less than a third"
            else:
                verdict = "makes it worse" if r_rec.high < 0 else "not significant"
            rows.append({"sequence": person, "tuning": tuning, "network": tuned, "metric": metric,
                         "clean_pre": float(e["clean"].mean()), "field_pre": float(e["field"].mean()),
                         "field_tuned": float(e["tuned"].mean()), "rise": r_rise.mean, "rise_low": r_rise.low,
                         "rise_high": r_rise.high, "recovered": r_rec.mean, "recovered_low": r_rec.low,
                         "recovered_high": r_rec.high, "share": share, "share_low": share_low,
                         "share_high": share_high, "frames": len(e), "verdict": verdict})
    return pd.DataFrame(rows)


#: Methods whose UAV2-in-UAV1 :func:`marker_table` measures against both references.
MARKER_METHODS = ("AirPose (pre-trained)", "AirPose", "AirPose+")
#: The method label of the markers' own row in :func:`marker_table`.
MARKERS_LABEL = "ArUco markers"


def uav2_in_uav1(exp: RecordingExperiment, person: str, methods=("AirPose", "AirPose+")) -> dict[str, np.ndarray]:
    """What notebook 05 plots: method -> ``(F, 3)`` UAV 2's position in UAV 1's camera frame from
    the two body poses, and :data:`MARKERS_LABEL` -> the markers' (NaN where they did not pose
    both drones) when the recording has markers."""
    lines = {m: relative_camera_positions(exp.estimates[person][m])[1] for m in methods}
    if (truth := exp.markers.get(person)) is not None:
        lines[MARKERS_LABEL] = np.where(np.asarray(truth["valid"], bool)[:, None], truth["t_12"], np.nan)
    return lines


def marker_table(exp: RecordingExperiment, methods=MARKER_METHODS) -> pd.DataFrame:
    """UAV 2 in UAV 1 from the ArUco markers: how good that truth is, and the methods against it.

    For each recording with markers (:attr:`RecordingExperiment.markers`): the markers against
    the generated cameras (where the recording has ground truth), then each method's UAV2-in-UAV1
    (:func:`~airpose_lib.eval.recordings.relative_camera_positions`) against the generated
    cameras and against the markers. Every row of a recording is over the same frames: those
    where the markers posed both drones and every network estimated both views
    (:func:`~airpose_lib.experiments.recordings.scored_frames`). Medians, as the target
    (a pose solver's rare flips would dominate a mean); the means beside them.

    Returns:
        columns ``sequence, method, reference`` ("generated cameras" or "markers"), ``frames``,
        ``frames_share`` (of the recording's frames), ``rel_t_median_m``, ``rel_rot_median_deg``,
        ``rel_t_mean_m``, ``rel_rot_mean_deg``, and for the markers' own row
        ``markers_median`` (markers detected per view) and ``rms_median_px``; empty without markers.
    """
    rows = []
    for person, truth in exp.markers.items():
        gt = exp.sequences[person].ground_truth
        keep = np.asarray(truth["valid"], bool) & scored_frames(exp.estimates[person])
        head = {"sequence": person, "frames": int(keep.sum()), "frames_share": float(keep.mean())}
        references = {"markers": (truth["R_12"], truth["t_12"])}
        if gt is not None:  # the cameras the renderer used: x_ck = R_cw x_w + t_cw
            references = {"generated cameras": relative_camera_from_markers(
                gt["R_cw"][:, 0], gt["t_cw"][:, 0], gt["R_cw"][:, 1], gt["t_cw"][:, 1]), **references}
            extra = {}
            if "count" in truth and keep.any():
                extra = {"markers_median": float(np.median(truth["count"][keep])),
                         "rms_median_px": float(np.nanmedian(truth["rms_px"][keep]))}
            rows.append({**head, "method": MARKERS_LABEL, "reference": "generated cameras",
                         **_relative_camera_errors(truth["R_12"], truth["t_12"], *references["generated cameras"],
                                                   keep), **extra})
        for m in methods:
            if m in exp.estimates[person]:
                R, t = relative_camera_positions(exp.estimates[person][m])
                rows += [{**head, "method": m, "reference": ref, **_relative_camera_errors(R, t, *pose, keep)}
                         for ref, pose in references.items()]
    columns = ["sequence", "method", "reference", "frames", "frames_share", *_RELATIVE_ERROR_COLUMNS]
    table = pd.DataFrame(rows)
    return table[columns + [c for c in table.columns if c not in columns]] if rows else table


_RELATIVE_ERROR_COLUMNS = ("rel_t_median_m", "rel_rot_median_deg", "rel_t_mean_m", "rel_rot_mean_deg")


def _relative_camera_errors(R, t, R_ref, t_ref, keep: np.ndarray) -> dict:
    """Median and mean UAV2-in-UAV1 errors over the frames ``keep`` ``(F,)`` (NaN over none)."""
    if not keep.any():
        return dict.fromkeys(_RELATIVE_ERROR_COLUMNS, float("nan"))
    t_err, r_err = relative_camera_errors_against(R[keep], t[keep], R_ref[keep], t_ref[keep])
    return dict(zip(_RELATIVE_ERROR_COLUMNS, (float(np.median(t_err)), float(np.median(r_err)),
                                              float(t_err.mean()), float(r_err.mean()))))


def claims_table(exp: RecordingExperiment, spin: str = "Baseline (pre-trained)") -> pd.DataFrame:
    """:func:`airpose_lib.eval.recordings.paper_claims` of the experiment (SPIN-style = ``spin``)."""
    depth = depth_summary(exp, {"SPIN-style": spin, "AirPose": "AirPose"})
    persons = exp.persons
    return paper_claims(exp.tables, depth, tuning=persons[0], test=persons[-1])


def markdown_table(table: pd.DataFrame, digits: int = 3) -> str:
    """A GitHub-flavoured Markdown table of a flat DataFrame (no ``tabulate`` needed)."""
    def fmt(v):
        return f"{v:.{digits}f}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(map(str, table.columns)) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in table.astype(object).itertuples(index=False)]
    return "\n".join(lines) + "\n"
