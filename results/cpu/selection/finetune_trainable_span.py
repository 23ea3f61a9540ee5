"""Issue 31, a choice and a measurement: field fine-tuning on the paper-span person 1 recording
(`cpu_tuning_paper_span.yaml`, 1,400 frames at 6 fps over 233 s) with the backbone's last block
trainable (trainable_from=layer4.1, backbone_lr_scale=0.1) against the frozen default, AirPose
and Baseline (cpu networks, seed 123).

    AIRPOSE_RUNS=RUNS python results/cpu/selection/finetune_trainable_span.py OUT

The choice, as `finetune_trainable_field.py` made it on the 900-frame recording: per network, the
setting with the lower held-out 2D error of person 1 at the step the selection rule keeps. Then,
for each setting (the measurement, never used for the choice), the share of the field person 2's
MPJPE rise that fine-tuning takes back, with its interval (`recording_tables.recovery_table`
against the cpu profile's clean experiment, which `tuning_paper_span.py` made).

Writes OUT/finetune_trainable_span.{csv,md}. One thread; finished runs and estimates in OUT are
reused."""
import sys
from pathlib import Path

import pandas as pd

from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.experiments.recording_tables import markdown_table, recovery_table
from airpose_lib.experiments.recordings import finetune_candidates, run_recording_experiment
from airpose_lib.train.ablation import trained_checkpoint

SPAN = str(Path(__file__).with_name("cpu_tuning_paper_span.yaml"))
CANDIDATES = {"frozen": {}, "layer4.1": {"trainable_from": "layer4.1", "backbone_lr_scale": 0.1}}
out = Path(sys.argv[1])
sequences = {"person1": ensure_sequences(SPAN, field=True, only=["person1"])["person1"],
             "person2": ensure_sequences("cpu", field=True, only=["person2"])["person2"]}
rows = pd.DataFrame(finetune_candidates("cpu", CANDIDATES, out / "runs", sequences=sequences))
rows["chosen"] = rows.groupby("network")["heldout_j2d_kept"].transform("min") == rows["heldout_j2d_kept"]
clean = run_recording_experiment("cpu")
parts = []
for name in CANDIDATES:
    networks = {"Baseline (pre-trained)": trained_checkpoint("cpu", "baseline", 123),
                "AirPose (pre-trained)": trained_checkpoint("cpu", "airpose", 123),
                "Baseline": out / "runs" / "baseline" / name / "checkpoints" / "best.pt",
                "AirPose": out / "runs" / "airpose" / name / "checkpoints" / "best.pt"}
    exp = run_recording_experiment("cpu", out / f"experiment_{name}", networks=networks, sequences=sequences,
                                   field=True)
    rec = recovery_table(clean, exp)
    parts.append(rec[rec["sequence"] == "person2"].assign(candidate=name))
recovery = pd.concat(parts, ignore_index=True)
recovery["network"] = recovery["network"].str.lower()
table = rows.merge(recovery[["network", "candidate", "rise", "recovered", "recovered_low", "recovered_high", "share",
                             "share_low", "share_high", "verdict"]], on=["network", "candidate"])
table.to_csv(out / "finetune_trainable_span.csv", index=False, lineterminator="\n")
(out / "finetune_trainable_span.md").write_text(
    "Field fine-tuning on the paper-span person 1 (1,400 frames at 6 fps), frozen backbone against its last block "
    "trainable: the choice's criterion (person 1's held-out 2D error at the kept step) and, never used for it, the "
    "share of the field person 2's MPJPE rise taken back (95 % block-bootstrap intervals over 1 s blocks).\n\n"
    + markdown_table(table, digits=4))
print(table.round(4).to_string())
