"""Generator of the synthetic two-drone still-frame dataset (the paper's ~30,000 AGORA frames,
here the open body model rendered off-screen).

One sample = one subject (gender, betas, pose, place and heading on the ground) seen by
``num_views`` independently placed drone cameras; per view the person crop is rendered directly
at the network input size with the crop's intrinsics, and the full-frame ground truth is stored
(see :class:`airpose_lib.data.still.dataset.StillFrameDataset` for the sample dict).

Reproducibility: shard ``k`` draws its sample attempts from ``numpy`` generators seeded with
``(seed, k, attempt)`` and keeps the first ``shard_size`` attempts whose person stays inside every
frame (the others are dropped and counted). A shard therefore depends only on the configuration
and its index: the same seed gives byte-identical shards whatever the number of workers, and an
interrupted run resumes by skipping the shards the manifest lists (after re-checking their
SHA-256) and rebuilding the rest.

Modules: ``config`` (:class:`GenerationConfig`, profile settings), ``frames`` (one
process's :class:`StillFrameGenerator`: sampling and rendering), this one (shards on disk, the
manifest, resumption and the worker pool).

Command line: ``airpose data generate --profile smoke|cpu|paper [--out DIR] [--workers N]``;
sizes come from the ``data: still:`` section of ``airpose_lib/profiles/<profile>.yaml``.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import queue as queue_mod
import sys
from pathlib import Path

from airpose_lib import __version__
from airpose_lib.folder_lock import MAKER_WAIT_S, folder_lock, locks_folder
from airpose_lib.process_guard import die_with_parent
from airpose_lib.progress import progress_bar

from .config import GENERATOR_VERSION, SPLITS, GenerationConfig
from .manifest import (
    DATASET_KIND,
    DatasetError,
    load_manifest,
    record_manifest,
    regenerate_command,
    shard_problem,
    write_manifest,
)
from .shards import sha256_file

__all__ = [
    # the settings live in .config; re-exported here because callers (CLI, training,
    # runtime, tests) import them from this entry point
    "GENERATOR_VERSION",
    "GenerationConfig",
    "generate_still_dataset",
    "ensure_still_dataset",
]


# -- parallel driver ------------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(config_dict: dict, progress_queue, parent: int | None = None) -> None:
    die_with_parent(parent)  # no orphaned renderers if the parent is killed (even before this runs)
    from .frames import StillFrameGenerator, _limit_threads  # heavy: see _run_inprocess

    os.environ.setdefault("LP_NUM_THREADS", "1")  # Mesa llvmpipe: one raster thread per worker
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _limit_threads()
    _WORKER["gen"] = StillFrameGenerator(GenerationConfig.from_dict(config_dict))
    _WORKER["queue"] = progress_queue


def _worker_shard(args: tuple[int, str]) -> dict:
    k, root = args
    q = _WORKER["queue"]
    return _WORKER["gen"].write_shard(k, Path(root), progress=lambda n: q.put(n))


def _body_model_hashes(config: GenerationConfig) -> dict[str, str]:
    """SHA-256 of the body-model file of each ground-truth gender (the data depend on it)."""
    from airpose_lib.body import check_model_file, resolve_model_file  # torch: see _run_inprocess

    return {g: sha256_file(check_model_file(resolve_model_file(config.body_source, g)))  # a damaged file
            for g in config.scene.genders}                                            # is named as such


def _new_manifest(config: GenerationConfig, label: str | None, body_models: dict) -> dict:
    return {
        "kind": DATASET_KIND,
        "generator_version": GENERATOR_VERSION,
        "kit_version": __version__,
        "profile": label,
        "seed": config.seed,
        "fingerprint": config.fingerprint(),
        "status": "incomplete",
        "num_samples": config.num_samples,
        "num_shards": config.num_shards,
        "shard_size": config.shard_size,
        "crop_size": config.crop_size,
        "num_views": config.scene.num_views,
        "image_format": config.image_format,
        "body_models": {"source": config.body_source, "sha256": body_models},
        "splits": {s: [k for k in range(config.num_shards) if config.shard_split(k) == s] for s in SPLITS},
        "totals": {},
        "config": config.to_dict(),
        "shards": [],
    }


def _finish_manifest(manifest: dict, config: GenerationConfig) -> None:
    shards = sorted(manifest["shards"], key=lambda r: r["index"])
    manifest["shards"] = shards
    samples = {s: sum(r["samples"] for r in shards if r["split"] == s) for s in SPLITS}
    attempts = sum(r["attempts"] for r in shards)
    dropped = sum(r["dropped"] for r in shards)
    manifest["totals"] = {
        "samples": sum(samples.values()), **{f"{s}_samples": n for s, n in samples.items()}, "attempts": attempts, "dropped": dropped,
        "drop_rate": round(dropped / attempts, 4) if attempts else 0.0,
        "bytes": sum(r["bytes"] for r in shards),
    }
    done = {r["index"] for r in shards}
    manifest["status"] = "complete" if done == set(range(config.num_shards)) else "incomplete"


@locks_folder("root", "dataset folder")  # one writer; removes a dead writer's .shard_*.tmp
def generate_still_dataset(
    config: GenerationConfig,
    root: Path | str,
    *,
    workers: int = 1,
    label: str | None = None,
    progress: bool = True,
    record: bool | Path = False,
    stop_after_shards: int | None = None,
) -> dict:
    """Generate (or resume, or just verify) a still-frame dataset in ``root``.

    Shards listed in ``root/manifest.yaml`` whose size and SHA-256 still match are kept; every
    other shard is (re)built. The manifest is rewritten after each finished shard.

    Args:
        config: what to generate.
        root: dataset folder (created if needed).
        workers: processes rendering shards in parallel, each with its own renderer (1 = in
            this process). The result does not depend on it.
        label: the profile's name recorded in the manifest (and used for the repair hint).
        progress: show a tqdm bar over samples.
        record: when the dataset is complete, copy the manifest to the checkout's
            ``data_manifests/generated_<profile>.yaml`` (True) or into the given folder.
        stop_after_shards: stop after building this many shards (simulates an interruption).

    Returns:
        The manifest dict (``status`` is ``complete`` unless stopped early).

    Raises:
        DatasetError: ``root`` holds a dataset made with other settings.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    manifest = load_manifest(root)
    if manifest is not None and manifest.get("fingerprint") != config.fingerprint():
        raise DatasetError(
            f"{root} holds a dataset made with other settings (profile {manifest.get('profile')!r}, "
            f"generator {manifest.get('generator_version')}); delete the folder or choose another "
            f"--out to generate this one")
    body_models = _body_model_hashes(config)
    if manifest is not None and (manifest.get("body_models") or {}).get("sha256") != body_models:
        raise DatasetError(
            f"{root} was generated with other body-model files than the ones in the cache now "
            f"(see body_models in {root / 'manifest.yaml'}); delete the folder or choose another "
            f"--out to generate the dataset again with the current model")
    if manifest is None:
        manifest = _new_manifest(config, label, body_models)
    if label is not None:
        manifest["profile"] = label

    kept, todo = [], []
    records = {r["index"]: r for r in manifest.get("shards") or []}
    for k in range(config.num_shards):
        r = records.get(k)
        problem = shard_problem(root, r) if r is not None else "is not made yet"
        if problem is None:
            kept.append(r)
        else:
            todo.append(k)
            if r is not None:  # a finished shard went bad: say so, not only rebuild it
                print(f"airpose: shard {root / r['file']} {problem}; rebuilding it", file=sys.stderr)
    manifest["shards"] = kept
    _finish_manifest(manifest, config)
    write_manifest(root, manifest)
    if todo and stop_after_shards is not None:
        todo = todo[:stop_after_shards]

    bar = None
    if progress and todo:
        bar = progress_bar(total=config.num_samples, initial=manifest["totals"]["samples"], unit="sample",
                   desc=f"still frames -> {root.name}", smoothing=0.1)

    def finished(rec: dict) -> None:
        manifest["shards"].append(rec)
        _finish_manifest(manifest, config)
        write_manifest(root, manifest)

    def recount() -> None:  # after a worker died mid-shard: its samples are rendered again
        if bar is not None:
            bar.n = manifest["totals"]["samples"]
            bar.refresh()

    try:
        if todo and workers <= 1:
            _run_inprocess(config, root, todo, bar, finished)
        elif todo:
            _run_pool(config, root, todo, min(workers, len(todo)), bar, finished, recount)
    finally:
        if bar is not None:
            bar.close()
    if manifest["status"] == "complete" and record:
        record_manifest(manifest, None if record is True else Path(record))
    return manifest


def _run_inprocess(config, root, todo, bar, finished) -> None:
    # .frames pulls in torch and smplx: imported here, not at the top, because a drone's
    # start-up imports this module and must stay light
    import torch

    from .frames import StillFrameGenerator, _limit_threads

    threads = torch.get_num_threads()
    _limit_threads()
    gen = StillFrameGenerator(config)
    try:
        for k in todo:
            finished(gen.write_shard(k, root, progress=bar.update if bar is not None else None))
    finally:
        gen.close()
        torch.set_num_threads(threads)


#: How many times the render workers are started again after one died (a native crash: one
#: worker of the cpu profile's 35,200-sample run segfaulted in libc, and the rerun rendered the
#: same shards without one). Only the unfinished shards are rendered again; a shard that keeps
#: killing its worker raises after that.
POOL_RESTARTS = 2


def _run_pool(config, root, todo, workers, bar, finished, recount=None) -> None:
    """Render the shards ``todo`` in ``workers`` spawned processes; ``finished(record)`` for each.

    A worker that dies (``BrokenProcessPool``) costs only the shards not yet finished: the pool is
    started again for them, up to :data:`POOL_RESTARTS` times, with a line on stderr; then
    ``recount()`` (if given) sets the progress bar back to what is finished.
    """
    from concurrent.futures.process import BrokenProcessPool

    todo, done = list(todo), set()

    def record(rec: dict) -> None:
        done.add(rec["index"])
        finished(rec)

    for restart in range(POOL_RESTARTS + 1):
        try:
            return _pool_once(config, root, [k for k in todo if k not in done], workers, bar, record)
        except BrokenProcessPool as e:
            left = [k for k in todo if k not in done]
            if restart == POOL_RESTARTS:
                raise
            print(f"airpose: a render worker died ({e}); starting the workers again for the {len(left)} "
                  f"unfinished shards of {root}", file=sys.stderr)
            if recount is not None:
                recount()


def _pool_once(config, root, todo, workers, bar, finished) -> None:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    # spawn: a fresh interpreter per worker, so no GL context or torch thread pool is inherited.
    # ProcessPoolExecutor (not multiprocessing.Pool): a worker that dies raises BrokenProcessPool
    # here instead of leaving its shard pending forever.
    ctx = mp.get_context("spawn")
    q = ctx.Queue()

    def drain() -> None:
        while True:
            try:
                n = q.get_nowait()
            except queue_mod.Empty:
                return
            if bar is not None:
                bar.update(n)

    ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(config.to_dict(), q, os.getpid()))
    try:
        pending = {ex.submit(_worker_shard, (k, str(root))) for k in todo}
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            drain()
            for f in done:
                finished(f.result())  # re-raises a worker's exception here
        drain()
    except BaseException:
        # Interrupted or failed: stop the other workers now; their unfinished shards leave only
        # temporary files, which the next run deletes.
        for p in list(getattr(ex, "_processes", {}).values()):
            p.terminate()
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    ex.shutdown(wait=True)


def ensure_still_dataset(config: GenerationConfig, root: Path | str, *, label: str | None = None,
                         workers: int | None = None, progress: bool = True, record: bool | Path = False,
                         wait_s: float = MAKER_WAIT_S) -> Path:
    """Make sure a complete, verified dataset of ``config`` exists in ``root`` and return the folder.

    A profile's dataset is ``ensure_still_dataset(configs.still, configs.folders.still)``
    (:class:`~airpose_lib.experiments.configs.KitConfigs`); ``label`` names the profile in the
    manifest of a new dataset. Every shard is verified once per process; damaged or missing ones
    are rebuilt (the kit owns this folder), so on a finished dataset this only checks checksums.
    While another process generates the same folder, this waits for it (a line on stderr says so)
    for at most ``wait_s`` seconds.

    Raises:
        FolderBusyError: the other process still holds the folder after ``wait_s``.
    """
    root = Path(root)
    if not record and _finished_and_intact(root, config):
        # Readers take no writer's lock (parallel trainings open the dataset at once).
        return root
    # Another process may be making this very dataset (two trainings or notebooks started side by
    # side on a fresh cache): wait for it, then look again before generating anything.
    with folder_lock(root, "dataset folder", wait=wait_s):
        if not record and _finished_and_intact(root, config):
            return root
        workers = workers if workers is not None else max(1, min(os.cpu_count() or 1, 4))
        manifest = generate_still_dataset(config, root, workers=workers, label=label,
                                          progress=progress, record=record)
    if manifest["status"] != "complete":
        raise DatasetError(f"dataset in {root} is incomplete; resume with "
                           f"`{regenerate_command(manifest, root)}`")
    return root


def _finished_and_intact(root: Path, config: GenerationConfig) -> bool:
    """Whether ``root`` holds the complete dataset of ``config`` with every shard as recorded (the
    generator names a damaged one when it rebuilds it)."""
    done = load_manifest(root)
    if done is None or done.get("status") != "complete" or done.get("fingerprint") != config.fingerprint():
        return False
    return all(shard_problem(root, rec) is None for rec in done.get("shards") or [])
