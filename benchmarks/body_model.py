"""Body-model benchmark: cold/warm build, smplx's full forward at batch 1 and 64, and the kit's
``body.forward.BodyForward`` paths: joints only at 2,000 (data, evaluation), full mesh at 64, the
training loss's subsampled mesh and joints (forward + backward at 64) and fitting's keypoints
(forward + backward at 1,000 frames, one shared beta).

    python benchmarks/body_model.py            # everything (cold build takes ~1-2 min)
    python benchmarks/body_model.py --no-cold  # skip the cold build

The cold build runs in a subprocess with empty kit and anny caches, so it includes anny's own
first build; the warm load is a fresh process loading the cached file. Timings are medians.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import torch


def _median_time(fn, repeat: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _subprocess_seconds(code: str, env: dict) -> float:
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True)
    return time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--no-cold", action="store_true", help="skip the cold build")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX, BodyForward, build_open_model, load_body_model
    from airpose_lib.body.forward import axis_angle_rotations

    rows = []
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
    if not args.no_cold:
        with tempfile.TemporaryDirectory() as tmp:
            cold_env = dict(env, AIRPOSE_CACHE=tmp, ANNY_CACHE_DIR=os.path.join(tmp, "anny"))
            seconds = _subprocess_seconds(
                "from airpose_lib.body import build_open_model; build_open_model()", cold_env
            )
        rows.append(("cold build, 3 genders (incl. anny's first build)", "-", f"{seconds:.1f} s"))
    build_open_model()  # make sure the warm cache exists
    load_code = "import time; t=time.perf_counter(); from airpose_lib.body import load_body_model; load_body_model(); print(time.perf_counter()-t)"
    out = subprocess.run([sys.executable, "-c", load_code], env=env, check=True, capture_output=True, text=True)
    rows.append(("warm load (import + load_body_model)", "-", f"{float(out.stdout.split()[-1]):.2f} s"))

    for batch in (1, 64):
        model = load_body_model(batch_size=batch)
        kw = dict(betas=torch.randn(batch, 10), body_pose=0.3 * torch.randn(batch, 63),
                  global_orient=torch.randn(batch, 3), transl=torch.randn(batch, 3))
        with torch.no_grad():
            t = _median_time(lambda model=model, kw=kw: model(**kw), args.repeat)
        rows.append(("smplx forward (full mesh)", str(batch), f"{t * 1e3:.1f} ms"))

    batch, chunk = 2000, 250
    model = load_body_model(batch_size=chunk)
    fast = BodyForward(model, range(76), vertices=None)
    kw = dict(betas=torch.randn(batch, 10), body_pose=0.3 * torch.randn(batch, 63),
              global_orient=torch.zeros(batch, 3), transl=torch.zeros(batch, 3))
    theta = axis_angle_rotations(kw["body_pose"])
    with torch.no_grad():
        t_fast = _median_time(lambda: fast(theta, kw["betas"]), args.repeat)

        def full():  # chunked: a single batch of 2,000 meshes needs several GB
            for s in range(0, batch, chunk):
                model(**{k: v[s : s + chunk] for k, v in kw.items()})

        t_full = _median_time(full, max(1, args.repeat // 2))
        mesh = BodyForward(model, range(76), "all")
        t_mesh = _median_time(lambda: mesh(theta[:64], kw["betas"][:64]), args.repeat)
    rows.append(("smplx forward (full mesh, chunks of 250)", str(batch), f"{t_full * 1e3:.0f} ms"))
    rows.append(("BodyForward joints only (76 joints)", str(batch), f"{t_fast * 1e3:.0f} ms"))
    rows.append(("speed-up of joints only", str(batch), f"{t_full / t_fast:.0f}x"))
    rows.append(("BodyForward full mesh + 76 joints", "64", f"{t_mesh * 1e3:.1f} ms"))

    def fwd_bwd(body, th, beta, vertices=True):
        th = th.clone().requires_grad_()
        j, v = body(th, beta, vertices=vertices)
        (j.sum() + (v.sum() if v is not None else 0)).backward()

    g = torch.Generator().manual_seed(0)
    ids = torch.randperm(model.v_template.shape[0], generator=g)[:1000].sort().values
    loss_sub, loss_full = BodyForward(model, vertices=ids), BodyForward(model)
    rows.append(("loss: 22 joints + 1,000 vertices, fwd+bwd", "64",
                 f"{_median_time(lambda: fwd_bwd(loss_sub, theta[:64], kw['betas'][:64]), args.repeat) * 1e3:.1f} ms"))
    rows.append(("loss: 22 joints + full mesh, fwd+bwd", "64",
                 f"{_median_time(lambda: fwd_bwd(loss_full, theta[:64], kw['betas'][:64]), args.repeat) * 1e3:.1f} ms"))
    rows.append(("loss: 22 joints only, fwd+bwd", "64",
                 f"{_median_time(lambda: fwd_bwd(loss_full, theta[:64], kw['betas'][:64], False), args.repeat) * 1e3:.1f} ms"))
    kp = BodyForward(model, sorted(i for i in set(BODY_25_FROM_SMPLX) | set(COCO18_FROM_SMPLX) if i >= 0), None)
    rows.append(("fitting: BODY_25 + COCO-18 keypoints, fwd+bwd", "1000",
                 f"{_median_time(lambda: fwd_bwd(kp, theta[:1000], kw['betas'][:1]), args.repeat) * 1e3:.0f} ms"))

    print(f"\nBody model benchmark ({args.threads} threads, torch {torch.__version__}, "
          f"{os.cpu_count()} cores)\n")
    print("| measurement | batch | time |")
    print("|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
