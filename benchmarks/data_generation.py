"""Still-frame generation throughput: two-view samples per second for 1 and 2 worker processes at
224 and 128 px crops.

    python benchmarks/data_generation.py                 # 96 samples per worker and setting
    python benchmarks/data_generation.py --samples 200 --sizes 224

Each worker process builds its generator (body models, renderer) and renders a warm-up shard
before the clock starts, then all start together; a setting's rate is all samples divided by the
slowest worker's wall time (steady state, what a long `airpose data generate` run achieves). The
CPU column is the workers' own CPU time per sample, which does not depend on what else runs on
the machine; the load average is printed with every row because other processes share the cores.
Finally one end-to-end `generate_still_dataset` run (spawn, model loading, shard writing
included) is timed for reference.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import tempfile
import time


def _worker(crop: int, samples: int, seed: int, ready, start, results) -> None:
    os.environ.setdefault("LP_NUM_THREADS", "1")
    from airpose_lib.data.still.config import GenerationConfig
    from airpose_lib.data.still.frames import StillFrameGenerator, _limit_threads

    _limit_threads()
    cfg = GenerationConfig(num_samples=samples + 4, shard_size=samples, crop_size=crop, seed=seed)
    gen = StillFrameGenerator(cfg)
    gen.make_shard(1)  # warm-up: the 4-sample last shard
    ready.set()
    start.wait()
    w0, c0 = time.perf_counter(), time.process_time()
    _, stats = gen.make_shard(0)
    results.put((stats["samples"], time.perf_counter() - w0, time.process_time() - c0, stats["dropped"]))
    gen.close()


def measure(crop: int, workers: int, samples: int) -> dict:
    """Steady-state rate of ``workers`` processes rendering ``samples`` samples each."""
    ctx = mp.get_context("spawn")
    start, results = ctx.Event(), ctx.Queue()
    readies = [ctx.Event() for _ in range(workers)]
    procs = [ctx.Process(target=_worker, args=(crop, samples, 1000 + w, readies[w], start, results))
             for w in range(workers)]
    for p in procs:
        p.start()
    for r in readies:
        r.wait()
    load0 = os.getloadavg()[0]
    start.set()
    out = [results.get() for _ in procs]
    for p in procs:
        p.join()
    n = sum(o[0] for o in out)
    wall = max(o[1] for o in out)
    return {"crop": crop, "workers": workers, "samples": n, "wall_s": wall, "rate": n / wall,
            "cpu_ms": 1e3 * sum(o[2] for o in out) / n, "dropped": sum(o[3] for o in out),
            "load": (load0, os.getloadavg()[0])}


def end_to_end(crop: int, workers: int, samples: int) -> tuple[float, float]:
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset

    cfg = GenerationConfig(num_samples=samples, shard_size=max(1, samples // (2 * workers)), crop_size=crop)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        generate_still_dataset(cfg, tmp, workers=workers, progress=False)
        wall = time.perf_counter() - t
    return wall, samples / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=96, help="timed samples per worker (default: 96)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[224, 128], help="crop sizes (default: 224 128)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts (default: 1 2)")
    parser.add_argument("--no-end-to-end", action="store_true", help="skip the end-to-end run")
    args = parser.parse_args()

    print(f"machine: {os.cpu_count()} CPU cores; load average now {os.getloadavg()}")
    print(f"{'crop':>5} {'workers':>7} {'samples':>7} {'wall s':>7} {'samples/s':>9} "
          f"{'CPU ms/sample':>13} {'CPU-bound samples/s on 2 free cores':>35} {'load avg 1 min (start->end)':>28}")
    for crop in args.sizes:
        for w in args.workers:
            r = measure(crop, w, args.samples)
            ideal = 2 * 1e3 / r["cpu_ms"]
            print(f"{crop:>5} {w:>7} {r['samples']:>7} {r['wall_s']:>7.1f} {r['rate']:>9.1f} "
                  f"{r['cpu_ms']:>13.1f} {ideal:>35.1f} {r['load'][0]:>13.2f} -> {r['load'][1]:.2f}", flush=True)
    if not args.no_end_to_end:
        wall, rate = end_to_end(args.sizes[0], max(args.workers), 2 * args.samples)
        print(f"end to end (generate_still_dataset, {max(args.workers)} workers, {2 * args.samples} samples at "
              f"{args.sizes[0]} px, incl. process start and model loading): {wall:.1f} s = {rate:.1f} samples/s; "
              f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
