"""Sequence generation benchmark: simulation (ground truth), detectors, rendering per scale.

    python benchmarks/sequence_generation.py                 # 60 frames, scales 0.25 0.5 1.0
    python benchmarks/sequence_generation.py --frames 120 --scales 0.5 --aa

Rendering throughput is reported as images per second (all views counted) and as frames per
second (a frame = one image per drone). The first frames of each renderer are a warm-up and
are not timed. Nothing is written to disk (JPEG encoding is not included).
"""
from __future__ import annotations

import argparse
import time

import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--scales", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    parser.add_argument("--aa", action="store_true", help="anti-aliasing on (default off)")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    from airpose_lib.data.sequences import SequenceConfig, SequenceRenderer, simulate_sequence
    from airpose_lib.data.sequences.detections import DEFAULT_DETECTORS, simulate_detections

    rows = []
    cfg = SequenceConfig(person="person2", n_frames=args.frames, seed=0)
    simulate_sequence(SequenceConfig(person="person2", n_frames=2))  # loads the model
    t = time.perf_counter()
    sim = simulate_sequence(cfg)
    rows.append((f"simulate {args.frames} frames x 2 views (ground truth)", f"{time.perf_counter() - t:.2f} s"))
    t = time.perf_counter()
    for k, det in enumerate(DEFAULT_DETECTORS.values()):
        simulate_detections(sim.gt, det, seed=k)
    rows.append(("both simulated detectors", f"{time.perf_counter() - t:.3f} s"))
    for scale in args.scales:
        cfg_s = SequenceConfig(person="person2", n_frames=args.frames, seed=0, render_scale=scale)
        sim_s = simulate_sequence(cfg_s)
        with SequenceRenderer(sim_s, anti_aliasing=args.aa) as r:
            list(r.render_frames(range(2)))  # warm-up
            t = time.perf_counter()
            n = sum(1 for _ in r.render_frames(range(2, args.frames)))
            dt = time.perf_counter() - t
        W, H = (int(x) for x in sim_s.gt["image_size"][0])
        rows.append((f"render {W}x{H}, AA {'on' if args.aa else 'off'}",
                     f"{2 * n / dt:.1f} images/s = {n / dt:.2f} frames/s"))
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")


if __name__ == "__main__":
    main()
