"""Issue 31 selection: field fine-tuning with the backbone's last block trainable
(trainable_from=layer4.1, backbone_lr_scale=0.1) against the frozen default, AirPose and Baseline,
chosen on person 1's held-out frames (the selection rule's held-out 2D error at the kept step);
person 2's errors per checkpoint logged as the diagnostic (never used for the choice).

    AIRPOSE_RUNS=/work/runs2 python results/cpu/selection/finetune_trainable_field.py OUT

(one thread; finished runs in OUT are reused) writes OUT/finetune_trainable_field.csv: per
network and backbone setting, the step the selection rule kept, person 1's held-out 2D error there,
and the field person 2's MPJPE before fine-tuning and at the kept step."""
import csv
import sys
from pathlib import Path

from airpose_lib.experiments.recordings import finetune_candidates

out = Path(sys.argv[1])
rows = [{"network": r["network"], "backbone": r["candidate"], "kept_step": r["kept_step"],
         "heldout_j2d_kept": r["heldout_j2d_kept"], "person2_mpjpe_before_m": r["person2_mpjpe_step0_m"],
         "person2_mpjpe_kept_m": r["person2_mpjpe_kept_m"]}
        for r in finetune_candidates("cpu", {"frozen": {}, "layer4.1": {"trainable_from": "layer4.1",
                                                                      "backbone_lr_scale": 0.1}}, out)]
with open(out / "finetune_trainable_field.csv", "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
