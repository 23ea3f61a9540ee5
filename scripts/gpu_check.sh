#!/usr/bin/env bash
# The kit's GPU checks in one run, on a machine with a CUDA GPU and a CUDA torch (README, "On a
# GPU"): what the CPU-only CI cannot exercise.
#
#   bash scripts/gpu_check.sh OUTDIR          # about 5 min on one H100-class GPU
#
# 1. env:    the GPU, torch, CUDA;
# 2. tests:  the engine's and the devices' tests with the GPU visible (device `auto` is then the
#            GPU): bit-identical resume, precision, device placement, torchrun, AirPose+ and the prior;
# 3. smoke:  the smoke profile on the GPU end to end: the shared backbone pretrained (bf16), the
#            AirPose regressor trained on its features (bf16), resumed bit for bit, evaluated;
# 4. bench:  one training step in fp32, bf16 and fp16 (+ channels_last), ResNet-18 @ 128 and the
#            paper's ResNet-50 @ 224 at the paper's batch of 30 two-view samples.
#
# Each step's output goes to OUTDIR/<step>.log and its status to OUTDIR/summary.md; a failed step
# does not stop the others. The data and the body model come from the kit cache (AIRPOSE_CACHE):
# the smoke dataset is generated first when missing (which needs the rendering dependencies).
set -u
OUT=${1:-gpu_check}
mkdir -p "$OUT"
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1 AIRPOSE_RUNS=${AIRPOSE_RUNS:-$OUT/runs}
summary="$OUT/summary.md"
echo "| step | status | seconds |" > "$summary"
echo "|---|---|---|" >> "$summary"

step() {  # step NAME TIMEOUT_S COMMAND...
    local name=$1 limit=$2
    shift 2
    local t0=$SECONDS
    echo "== $name: $*"
    timeout "$limit" bash -c "$*" > "$OUT/$name.log" 2>&1
    local rc=$?
    echo "| $name | $([ $rc -eq 0 ] && echo ok || echo "FAILED (exit $rc)") | $((SECONDS - t0)) |" >> "$summary"
    tail -n 30 "$OUT/$name.log"
}

step env 60 "nvidia-smi -L; $PY -c 'import torch; print(torch.__version__, torch.version.cuda, \
torch.cuda.get_device_name(0), torch.cuda.device_count(), \"GPU(s)\")'"

step tests 420 "$PY -m pytest -q -p no:cacheprovider -m 'not slow' tests/test_train_loop.py tests/test_engine.py \
tests/test_precision_device.py tests/test_device_stages.py tests/test_torchrun.py tests/test_fitting_airpose_plus.py"

# The smoke profile on the GPU: the backbone (device auto), a bit-identical resume, an evaluation.
step smoke 420 "set -e
$PY -m airpose_lib.cli pretrain --profile smoke --quiet
$PY scripts/gpu_resume_check.py $AIRPOSE_RUNS --device cuda --precision bf16
$PY -m airpose_lib.cli eval --checkpoint $AIRPOSE_RUNS/straight/checkpoints/last.pt --split val --device cuda"

step bench 300 "$PY benchmarks/training_precision.py --device cuda --batch 30 --repeat 10"

cat "$summary"
