"""Table I's mechanism on the validation split: what the features and the trained variants carry
that an exchange between the views could average (the pieces: :mod:`airpose_lib.eval.mechanism`).

One long table, one row per measurement:

* part ``a``, probes of the profile's backbone: stature (the subject's T-posed body, its gender's
  model, ``eval.mean_body.rest_statures``), gender (female = 1) and log depth ``log tau_z``, each
  read from one view's pooled features, with and without the crop vector P, by ridge and by a small
  MLP, fitted on the training split's features when they are cached (else on two thirds of the
  validation subjects) and scored on validation subjects it never saw; the correlation between
  the two views' errors (stature; relative depth);
* part ``b``, each trained variant's predicted body: the stature of the neutral body with the
  predicted beta, per regressor iteration (stage), against the true stature;
* part ``c``, each variant's depth: the two views' relative depth errors, their correlation, and
  the MPE if each view's relative depth error were the views' mean (what exchanging a body scalar
  can buy at most) or zero (a perfect depth scale), against the measured MPE, with the relative
  gains' paired intervals;
* part ``d``, each variant's MPJPE: Table I's (its predicted root orientation) and with the true
  root orientation (the body pose alone), and for each of the paper's MPJPE orderings the paired
  gain three ways: as Table I scores it, both methods with the true root, and the second method
  with the true root (the most an exact root orientation could give it).

Intervals: 95 % bootstrap over two-view validation samples. Never reads the test split.
:func:`write_mechanism_table` runs it and writes ``mechanism.csv``, ``mechanism.md`` and
``provenance.json`` into a folder (``results/cpu/mechanism/`` for the committed table).
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from airpose_lib.data.still.dataset import split_arrays
from airpose_lib.eval.ablation import VARIANT_LABELS, table_to_markdown
from airpose_lib.eval.mean_body import rest_statures
from airpose_lib.eval.mechanism import (
    accuracy,
    depth_scaled,
    fit_mlp,
    fit_ridge,
    probe_interval,
    r2_score,
    relative_depth_error,
    view_error_correlation,
)
from airpose_lib.eval.metrics import translation_error
from airpose_lib.eval.reference import RESULTS_ROOT, git_commit, provenance_record, reference_outputs
from airpose_lib.eval.significance import PAPER_ORDER, bootstrap_interval, paired_bootstrap
from airpose_lib.model import to_smplx_params
from airpose_lib.train.evaluate import evaluate_features, load_network
from airpose_lib.train.features import ensure_features, features_path
from airpose_lib.train.pretrain import profile_backbone

from .configs import KitConfigs

__all__ = ["COLUMNS", "probe_rows", "variant_rows", "body_pose_rows", "mechanism_table", "write_mechanism_table"]

#: Columns of the table, in order.
COLUMNS = ("part", "quantity", "input", "readout", "metric", "value", "CI low", "CI high", "samples")
_ARRAYS = ("beta", "gender", "tau", "P", "K")


def _row(part, quantity, inp, readout, metric, interval, samples) -> dict:
    value, low, high = interval
    return dict(zip(COLUMNS, (part, quantity, inp, readout, metric, value, low, high, samples)))


def _mean_interval(x: np.ndarray, n_resamples: int) -> tuple[float, float, float]:
    """Mean over samples of ``x (N, ...)`` (each row one two-view sample) with its interval."""
    x = np.asarray(x, dtype=np.float64).reshape(len(x), -1).mean(1)
    return bootstrap_interval(lambda idx: float(x[idx].mean()), len(x), n_resamples)


def _targets(arrays: dict, stature: np.ndarray) -> dict[str, np.ndarray]:
    """Probe targets per sample and view, ``(N, V)``."""
    V = arrays["tau"].shape[1]
    per_sample = lambda a: np.repeat(np.asarray(a, dtype=np.float64)[:, None], V, axis=1)  # noqa: E731
    return {"stature [m]": per_sample(stature), "gender (female = 1)": per_sample(arrays["gender"] == 2),
            "log depth": np.log(arrays["tau"][..., 2].astype(np.float64))}


def _inputs(features: np.ndarray, arrays: dict) -> dict[str, np.ndarray]:
    """Probe inputs per sample and view, ``(N, V, d)``."""
    f = np.asarray(features, dtype=np.float64)
    return {"features": f, "features + P": np.concatenate([f, np.asarray(arrays["P"], np.float64)], axis=-1)}


def _probe_metrics(quantity: str, truth: np.ndarray, pred: np.ndarray, n_resamples: int) -> list[tuple]:
    """``(metric, (value, low, high))`` of one probe's ``(N, V)`` predictions on held-out samples."""
    out = [("R2", probe_interval(r2_score, truth, pred, n_resamples))]
    if quantity.startswith("gender"):
        out.append(("accuracy", probe_interval(accuracy, truth, pred, n_resamples)))
    elif quantity.startswith("stature"):
        out.append(("view error correlation",
                    probe_interval(lambda t, p: view_error_correlation(p - t), truth, pred, n_resamples)))
        # what fusing the views' readings (an exchange of the estimate) adds to one view's
        out.append(("R2 of the views' mean",
                    probe_interval(lambda t, p: r2_score(t[:, 0], p.mean(1)), truth, pred, n_resamples)))
    else:
        rel = np.exp(pred - truth) - 1.0  # log depth -> (z_pred - z) / z
        out.append(("view error correlation (relative depth)",
                    probe_interval(lambda r, _: view_error_correlation(r), rel, rel, n_resamples)))
    return out


def probe_rows(fit: tuple[np.ndarray, dict, np.ndarray], score: tuple[np.ndarray, dict, np.ndarray],
               n_resamples: int = 2000, mlp_steps: int = 400, log: Callable[[str], None] = print) -> list[dict]:
    """Part ``a``: every probe fitted on ``fit`` and scored on ``score``.

    Args:
        fit, score: ``(features (N, V, C), arrays, stature (N,))``: the arrays of
            :func:`~airpose_lib.data.still.dataset.split_arrays` (``gender``, ``tau``, ``P``) of the
            same samples, in the features' order, and each sample's true stature.
        n_resamples: bootstrap resamples of the intervals (over ``score``'s samples).
        mlp_steps: training steps of each MLP probe.
    """
    (f_fit, a_fit, s_fit), (f_score, a_score, s_score) = fit, score
    y_fit, y_score = _targets(a_fit, s_fit), _targets(a_score, s_score)
    x_fit, x_score = _inputs(f_fit, a_fit), _inputs(f_score, a_score)
    readouts = {"ridge": fit_ridge, "MLP": lambda X, y: fit_mlp(X, y, steps=mlp_steps)}
    n, rows = len(f_score), []
    for quantity in y_fit:
        for inp in x_fit:
            for name, fitter in readouts.items():
                t0 = time.time()
                X = x_fit[inp].reshape(-1, x_fit[inp].shape[-1])  # (sample, view) rows: views stay together
                probe = fitter(X, y_fit[quantity].ravel())
                pred = probe(x_score[inp].reshape(-1, x_score[inp].shape[-1])).reshape(y_score[quantity].shape)
                truth = y_score[quantity]
                rows += [_row("a", quantity, inp, name, metric, iv, n)
                         for metric, iv in _probe_metrics(quantity, truth, pred, n_resamples)]
                log(f"probe {quantity} | {inp} | {name}: R2 {r2_score(truth, pred):.3f} "
                    f"({time.time() - t0:.0f} s, {probe.note})")
    return rows


@torch.no_grad()
def _regress(checkpoint: Path, features: np.ndarray, arrays: dict,
             batch_size: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """A checkpoint's regressor on cached features (``(N, V, C)`` pooled, or ``(N, V, C, h, w)``
    the input of the first block it trains): tau ``(N, V, 3)`` (the final estimate, camera
    frame, as Table I scores it) and beta per iteration ``(iterations, N, V, 10)`` (from the
    messages every view sends after each iteration)."""
    model, record, state = load_network(checkpoint, "cpu")
    cut = state["config"].get("trainable_from")
    taus, betas = [], []
    for start in range(0, len(features), batch_size):
        sl = slice(start, start + batch_size)
        P, K = torch.as_tensor(arrays["P"][sl]), torch.as_tensor(arrays["K"][sl])
        f = torch.as_tensor(np.array(features[sl], dtype=np.float32))  # a copy: mmap is read-only
        out = model.regress(f if cut is None else model.features_from(f, cut), P)
        taus.append(to_smplx_params(out, P, K, input_size=record.input_size)["tau"].double().numpy())
        betas.append(torch.stack([m[..., -10:] for m in out["messages"]]).double().numpy())
    return np.concatenate(taus), np.concatenate(betas, axis=1)


def variant_rows(variant: str, checkpoint: Path, features: np.ndarray, arrays: dict, stature: np.ndarray,
                 stages: Sequence[int] | None = None, n_resamples: int = 2000,
                 log: Callable[[str], None] = print) -> list[dict]:
    """Parts ``b`` and ``c`` for one trained variant on a split's cached features.

    Args:
        variant: its name (``airpose`` ...); checkpoint: its ``last.pt``.
        features: ``(N, V, C)``; arrays: ``tau``, ``P``, ``K`` of the same samples; stature ``(N,)``.
        stages: the iterations (1-based) whose predicted stature is scored (None: the last only).
    """
    label, n, rows = VARIANT_LABELS[variant], len(features), []
    tau, betas = _regress(checkpoint, features, arrays)
    V = tau.shape[1]
    truth = np.repeat(np.asarray(stature, dtype=np.float64)[:, None], V, axis=1)
    for k in stages or (len(betas),):
        neutral = np.zeros(n * V, dtype=np.int64)
        pred, _ = rest_statures(betas[k - 1].reshape(n * V, -1), neutral)
        pred = pred.reshape(n, V)
        inp = f"stage {k}"
        rows.append(_row("b", "predicted stature [m]", inp, label, "R2", probe_interval(r2_score, truth, pred,
                                                                                        n_resamples), n))
        rows.append(_row("b", "predicted stature [m]", inp, label, "correlation with true stature",
                         probe_interval(lambda t, p: float(np.corrcoef(t.ravel(), p.ravel())[0, 1]), truth, pred,
                                        n_resamples), n))
        log(f"{label} stage {k}: stature R2 {rows[-2]['value']:.3f}, correlation {rows[-1]['value']:.3f}")
    tau_true = np.asarray(arrays["tau"], dtype=np.float64)
    rel = relative_depth_error(tau, tau_true)
    rows.append(_row("c", "relative depth error", "final", label, "view error correlation",
                     probe_interval(lambda r, _: view_error_correlation(r), rel, rel, n_resamples), n))
    rows.append(_row("c", "relative depth error", "final", label, "mean absolute error [%]",
                     _mean_interval(100 * np.abs(rel), n_resamples), n))
    err = lambda t: translation_error(torch.as_tensor(t), torch.as_tensor(tau_true)).numpy().mean(1)  # noqa: E731
    measured = err(tau)
    rows.append(_row("c", "MPE [m]", "measured", label, "MPE [m]", _mean_interval(measured, n_resamples), n))
    for name, shared in (("views' mean relative depth error (shared scalar)", True), ("exact depth scale", False)):
        other = err(depth_scaled(tau, tau_true, shared=shared))
        rows.append(_row("c", "MPE [m]", name, label, "MPE [m]", _mean_interval(other, n_resamples), n))
        r = paired_bootstrap(measured - other, n_resamples, base=measured)
        rows.append(_row("c", "MPE [m]", name, label, "gain over measured [%]",
                         (100 * r.relative, 100 * r.relative_low, 100 * r.relative_high), n))
    log(f"{label}: MPE {rows[-5]['value']:.3f} m, shared-scalar gain {rows[-3]['value']:.1f} %, "
        f"exact-scale gain {rows[-1]['value']:.1f} %")
    return rows


#: Part ``d``'s ways of scoring an MPJPE ordering "A > B": (input, A's column, B's column).
_POSE_GAINS = (("predicted root (Table I)", "mpjpe_m", "mpjpe_m"),
               ("true root for both (the body pose alone)", "mpjpe_true_root_m", "mpjpe_true_root_m"),
               ("true root for the second (an exact root orientation)", "mpjpe_m", "mpjpe_true_root_m"))


def body_pose_rows(per_view: Mapping[str, pd.DataFrame], n_resamples: int = 2000,
                   log: Callable[[str], None] = print) -> list[dict]:
    """Part ``d``: what each variant's MPJPE is made of, and what the paper's MPJPE orderings rest on.

    Args:
        per_view: variant -> its per-view table on one split
            (:func:`~airpose_lib.eval.tables.per_view_table`: ``sample``, ``view``, ``mpjpe_m``,
            ``mpjpe_true_root_m``), every variant on the same samples.
    Returns:
        per variant, Table I's MPJPE and the true-root MPJPE (mean over samples, interval); per
        ordering of :data:`~airpose_lib.eval.significance.PAPER_ORDER` whose two variants are
        given, the relative gain ``(e_A - e_B) / e_A`` of each of :data:`_POSE_GAINS`, paired over
        two-view samples (a sample's error is its views' mean).
    """
    rows, sample = [], lambda t, col: t.groupby("sample")[col].mean().sort_index()  # noqa: E731
    for variant, table in per_view.items():
        label = VARIANT_LABELS[variant]
        for inp, col in (("predicted root (Table I)", "mpjpe_m"), ("true root (the body pose alone)", "mpjpe_true_root_m")):
            x = sample(table, col).to_numpy()
            rows.append(_row("d", "MPJPE [m]", inp, label, "MPJPE [m]", _mean_interval(x, n_resamples), len(x)))
    present = [v for v in PAPER_ORDER if v in per_view]
    for a, b in zip(present, present[1:]):
        pair = f"{VARIANT_LABELS[a]} > {VARIANT_LABELS[b]}"
        for inp, col_a, col_b in _POSE_GAINS:
            e_a, e_b = sample(per_view[a], col_a), sample(per_view[b], col_b)
            if not e_a.index.equals(e_b.index):
                raise ValueError(f"{a} and {b} were scored on different samples")
            r = paired_bootstrap(e_a.to_numpy() - e_b.to_numpy(), n_resamples, base=e_a.to_numpy())
            rows.append(_row("d", "MPJPE gain", inp, pair, "gain [%]",
                             (100 * r.relative, 100 * r.relative_low, 100 * r.relative_high), len(e_a)))
        log(f"MPJPE {pair}: gain {rows[-3]['value']:.1f} %, body pose alone {rows[-2]['value']:.1f} %, "
            f"exact root for the second {rows[-1]['value']:.1f} %")
    return rows


def _checkpoint(configs: KitConfigs, variant: str, seed: int) -> Path | None:
    """A finished run's final checkpoint (None while it trains or when it never ran)."""
    result = configs.folders.train(variant, seed) / "result.json"
    if not result.is_file():
        return None
    checkpoint = json.loads(result.read_text()).get("checkpoint")
    return Path(checkpoint) if checkpoint and Path(checkpoint).is_file() else None


def _portable(path: str | Path) -> str:
    """A checkpoint's path below the runs folder (``train/<profile>/...``): no machine's folders in results."""
    parts = Path(path).parts
    return "/".join(parts[parts.index("train"):]) if "train" in parts else Path(path).name


def mechanism_table(configs: KitConfigs, seed: int = 123, variants: Sequence[str] = PAPER_ORDER,
                    fit_split: str = "auto", fit_samples: int | None = None, n_resamples: int = 2000,
                    mlp_steps: int = 400, checkpoints: Mapping[str, str | Path] | None = None,
                    log: Callable[[str], None] = print) -> tuple[pd.DataFrame, dict]:
    """The mechanism table of a profile's backbone and its trained variants (seed ``seed``) on the
    validation split.

    Args:
        configs: the profile's configs (:func:`airpose_lib.reproduce.configs.kit_configs`).
        fit_split: where the probes are fitted: ``"train"`` (the first ``fit_samples`` training
            samples, None: all; their features are computed if missing), ``"val"`` (two thirds of the validation
            subjects, drawn with a fixed seed; the others are scored), ``"auto"``: train when its
            feature file is cached, else val.
        variants: those whose finished run exists are measured (the others are listed in the notes).
        checkpoints: variant -> its network (e.g. notebook 02's runs); None: the profile's finished
            runs of ``seed`` in ``<runs>/train/<profile>/``.
    Returns:
        ``(table, notes)``: rows as :data:`COLUMNS` (the module docstring), and what was measured on
        what (backbone, fit and score samples, variants and checkpoints, wall times).
    """
    t_start = time.time()
    root, backbone = configs.folders.still, profile_backbone(configs.pretrain)
    if fit_split == "auto":
        fit_split = "train" if features_path(backbone, root, "train").is_file() else "val"
    val_feat = np.load(ensure_features(backbone, root, "val"), mmap_mode="r")
    val = split_arrays(root, "val", _ARRAYS)
    val_stature, _ = rest_statures(val["beta"], val["gender"])
    if fit_split == "train":
        fit_feat = np.load(ensure_features(backbone, root, "train"), mmap_mode="r")[:fit_samples]
        fit_arrays = split_arrays(root, "train", _ARRAYS, max_samples=fit_samples)
        fit = (np.asarray(fit_feat), fit_arrays, rest_statures(fit_arrays["beta"], fit_arrays["gender"])[0])
        score = (np.asarray(val_feat), val, val_stature)
        fit_note = f"train split, {len(fit_feat)} samples; scored on all {len(val_feat)} validation samples"
    elif fit_split == "val":
        order = np.random.default_rng(0).permutation(len(val_feat))
        cut = 2 * len(order) // 3
        pick = lambda idx: (np.asarray(val_feat)[idx], {k: v[idx] for k, v in val.items()}, val_stature[idx])  # noqa: E731
        fit, score = pick(np.sort(order[:cut])), pick(np.sort(order[cut:]))
        fit_note = f"validation split, {cut} subjects; scored on the other {len(order) - cut}"
    else:
        raise ValueError(f"fit_split must be 'auto', 'train' or 'val', got {fit_split!r}")
    log(f"probes: {fit_note}")
    rows = probe_rows(fit, score, n_resamples, mlp_steps, log)
    walls = {"probes": round(time.time() - t_start, 1)}
    done, per_view = {}, {}
    for variant in variants:
        checkpoint = _checkpoint(configs, variant, seed) if checkpoints is None else checkpoints.get(variant)
        if checkpoint is None:
            log(f"{variant} seed {seed}: no finished run, left out")
            continue
        t0 = time.time()
        config = load_network(checkpoint, "cpu")[2]["config"]
        model_backbone, cut = Path(str(config.get("pretrained"))), config.get("trainable_from")
        same = cut is None and model_backbone.is_file() and model_backbone.stem == backbone.stem
        feats = val_feat if same else np.load(ensure_features(model_backbone, root, "val", cut=cut), mmap_mode="r")
        stages = None if variant != "airpose" else range(1, 4)
        rows += variant_rows(variant, checkpoint, feats, val, val_stature, stages, n_resamples, log)
        per_view[variant] = evaluate_features(checkpoint, model_backbone, root, VARIANT_LABELS[variant],
                                              split="val")["per_view"]
        done[variant] = _portable(checkpoint)
        walls[variant] = round(time.time() - t0, 1)
    rows += body_pose_rows(per_view, n_resamples, log)
    notes = {"profile": configs.label, "split": "val", "backbone": backbone.stem, "probes fitted on": fit_note,
             "seed": seed, "variants": done, "variants left out": [v for v in variants if v not in done],
             "n_resamples": n_resamples, "mlp_steps": mlp_steps, "wall_s": walls}
    return pd.DataFrame(rows, columns=list(COLUMNS)), notes


def write_mechanism_table(out_dir: str | Path, configs: KitConfigs, command: str | None = None,
                          **kwargs) -> tuple[pd.DataFrame, Path]:
    """Run :func:`mechanism_table` and write ``mechanism.csv``, ``mechanism.md`` and ``provenance.json``
    (commit, command, what was measured on what) into ``out_dir``.

    Args:
        command: the command recorded (default: the Python call that makes it again).
        kwargs: of :func:`mechanism_table`.
    """
    out = Path(out_dir)
    profile = configs.label
    command = command or (f"python -c \"from airpose_lib.experiments.mechanism import write_mechanism_table; "
                          f"from airpose_lib.reproduce.configs import kit_configs; "
                          f"write_mechanism_table('{out.as_posix()}', kit_configs('{profile}'))\"")
    table, notes = mechanism_table(configs, **kwargs)
    out.mkdir(parents=True, exist_ok=True)
    try:
        rel = out.resolve().relative_to(RESULTS_ROOT.parent).as_posix() + "/"
    except ValueError:  # a folder outside the checkout: nothing of it is tracked
        rel = ""
    record = provenance_record(profile, command)
    record["git"] = git_commit(outputs=(*reference_outputs(profile), rel) if rel else reference_outputs(profile))
    table.to_csv(out / "mechanism.csv", index=False)
    heading = (f"Mechanism of Table I on the validation split (profile {profile}, seed {notes['seed']}); "
               f"probes fitted on the {notes['probes fitted on']}; 95 % bootstrap intervals over two-view samples.")
    (out / "mechanism.md").write_text(heading + "\n\n" + table_to_markdown(table.set_index("part"), digits=4))
    (out / "provenance.json").write_text(json.dumps({**record, **notes}, indent=2) + "\n")
    return table, out
