"""Body-model benchmark: cold/warm build, full forward at batch 1 and 64, joints-only at 2,000.

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

    from airpose_lib.body import build_open_model, load_body_model
    from airpose_lib.body.fast import JointsOnly

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
            t = _median_time(lambda: model(**kw), args.repeat)
        rows.append(("smplx forward (full mesh)", str(batch), f"{t * 1e3:.1f} ms"))

    batch, chunk = 2000, 250
    model = load_body_model(batch_size=chunk)
    fast = JointsOnly(model)
    kw = dict(betas=torch.randn(batch, 10), body_pose=0.3 * torch.randn(batch, 63),
              global_orient=torch.randn(batch, 3), transl=torch.randn(batch, 3))
    with torch.no_grad():
        t_fast = _median_time(lambda: fast(**kw), args.repeat)

        def full():  # chunked: a single batch of 2,000 meshes needs several GB
            for s in range(0, batch, chunk):
                model(**{k: v[s : s + chunk] for k, v in kw.items()})

        t_full = _median_time(full, max(1, args.repeat // 2))
    rows.append(("smplx forward (full mesh, chunks of 250)", str(batch), f"{t_full * 1e3:.0f} ms"))
    rows.append(("joints-only fast path (76 joints)", str(batch), f"{t_fast * 1e3:.0f} ms"))
    rows.append(("speed-up of the fast path", str(batch), f"{t_full / t_fast:.0f}x"))

    print(f"\nBody model benchmark ({args.threads} threads, torch {torch.__version__}, "
          f"{os.cpu_count()} cores)\n")
    print("| measurement | batch | time |")
    print("|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
