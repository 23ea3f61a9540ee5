#!/usr/bin/env bash
# The demo's verdicts on the other kernel path (run after `make demo`): notebooks 02 and 05 again
# with the CPU limited to AVX2 (the kernels an AVX2-only machine runs) and one thread, in a fresh
# run folder and a cache that shares only the body model and the rendered data, so that the
# features, the networks' checkpoints and every estimate are computed anew. Exits 1 when either
# notebook finds the run outside the tolerances of results/cpu/: a verdict that depended on the
# kernel path or the thread count would fail here.
set -euo pipefail
cd "$(dirname "$0")/.."
cache=${AIRPOSE_CACHE:-$HOME/.cache/airpose}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/cache/data"
ln -s "$cache/body" "$tmp/cache/body"
for d in "$cache"/data/still_demo "$cache"/data/sequences_demo*; do
  [ -d "$d" ] || { echo "no $d: run make demo first" >&2; exit 2; }
  ln -s "$d" "$tmp/cache/data/"
done
echo "kernel path: ONEDNN_MAX_CPU_ISA=AVX2 ATEN_CPU_CAPABILITY=avx2, one thread; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
start=$(date +%s)
ONEDNN_MAX_CPU_ISA=AVX2 ATEN_CPU_CAPABILITY=avx2 OMP_NUM_THREADS=1 \
  AIRPOSE_CACHE="$tmp/cache" AIRPOSE_RUNS="$tmp/runs" \
  .venv/bin/airpose reproduce --profile demo --only 02 05 --require-agreement --figures "$tmp/figures"
echo "other kernel path: $(( $(date +%s) - start )) s; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
# what the other kernels' rounding moved, beside the tolerances it must stay within
runs=${AIRPOSE_RUNS:-runs}
.venv/bin/python - "$runs/demo/02_ablation_table/table1_ablation.csv" "$tmp/runs/demo/02_ablation_table/table1_ablation.csv" <<'PY'
import sys

import pandas as pd

a, b = (pd.read_csv(f, index_col=0) for f in sys.argv[1:3])
rows = [m for m in a.index if pd.notna(a.loc[m, "MPJPE [m]"])]
for col in ("MPE [m]", "MPJPE [m]"):
    rel = ((b.loc[rows, col] - a.loc[rows, col]) / a.loc[rows, col]).abs().max()
    print(f"{col}: largest relative difference between the kernel paths {100 * rel:.2g} % (tolerance 5 %)")
deg = (b.loc[rows, "root orient. median [deg]"] - a.loc[rows, "root orient. median [deg]"]).abs().max()
print(f"root orient. median: largest difference {deg:.2g} deg (tolerance 1 deg)")
PY
