"""Issue 31 selection: field fine-tuning with the backbone's last block trainable
(trainable_from=layer4.1, backbone_lr_scale=0.1) against the frozen default, AirPose and Baseline,
chosen on person 1's held-out frames (the selection rule's held-out 2D error at the kept step);
person 2's errors per checkpoint logged as the diagnostic (never used for the choice).

    AIRPOSE_RUNS=/work/runs2 python results/cpu/selection/finetune_trainable_field.py OUT

(one thread; finished runs in OUT are reused) writes OUT/finetune_trainable_field.csv: per
network and backbone setting, the step the selection rule kept, person 1's held-out 2D error there,
and the field person 2's MPJPE before fine-tuning and at the kept step."""
import csv
import dataclasses
import sys
from pathlib import Path

from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.experiments.recordings import _finetune_logged, _tests_key, recording_prior, trained_checkpoint
from airpose_lib.finetune.config import finetune_config
from airpose_lib.train import load_train_config

out = Path(sys.argv[1])
profile = "cpu"
seqs = {n: load_sequence(p) for n, p in ensure_sequences(profile, field=True).items()}
tuning, tests = seqs["person1"], {"person2": seqs["person2"]}
prior, prior_info = recording_prior(profile, False)
seed = load_train_config(profile, "airpose").seed
base = dataclasses.replace(finetune_config(profile), prior=prior_info["source"], prior_path=prior_info["file"])
key = _tests_key(tests)
rows = []
for variant in ("airpose", "baseline"):
    pre = trained_checkpoint(profile, variant, seed)
    for name, cfg in (("frozen", base),
                      ("layer4.1", dataclasses.replace(base, trainable_from="layer4.1", backbone_lr_scale=0.1))):
        res, info = _finetune_logged(pre, tuning, tests, cfg, out / variant / name, prior, False, key)
        log = {int(r["step"]): r for r in csv.DictReader(open(out / variant / name / "selection.csv"))}
        kept = int(info["selected_step"])
        rows.append({"network": variant, "backbone": name, "kept_step": kept,
                     "heldout_j2d_kept": round(float(info["heldout_j2d"]), 2),
                     "person2_mpjpe_before_m": round(float(log[0]["diag_person2_mpjpe_m"]), 4),
                     "person2_mpjpe_kept_m": round(float(log[kept]["diag_person2_mpjpe_m"]), 4)})
        print(rows[-1], flush=True)
with open(out / "finetune_trainable_field.csv", "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
