"""Issue 31, a measurement (no choice): does the paper's fine-tuning close the field gap on the
person it is tuned on? A positive control for the fine-tuning itself, beside the transfer from
person 1 to person 2 that the issue's target asks for.

    AIRPOSE_RUNS=RUNS python results/cpu/selection/finetune_same_person.py OUT

AirPose and Baseline (cpu networks, seed 123) fine-tuned with the cpu profile's settings on the
first 720 frames (24 s) of the field person 2 (`frames: [0, 720]`; the selection rule's held-out
frames are the last 20 % of those, 576-719), then measured on frames 720-899 (the last 6 s),
which the fine-tuning never saw: the share of the field rise taken back there
(`recording_tables.recovery_table` with `frames`, against the cpu clean experiment, which
`tuning_paper_span.py` made); and on the frames it trained on (0-575), for comparison. Writes OUT/finetune_same_person.{csv,md}. One thread."""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.experiments.recording_tables import markdown_table, recovery_table
from airpose_lib.experiments.recordings import finetune_candidates, run_recording_experiment
from airpose_lib.train.ablation import trained_checkpoint

TUNE, TRAINED, TEST = [0, 720], np.arange(0, 576), np.arange(720, 900)
out = Path(sys.argv[1])
person2 = ensure_sequences("cpu", field=True, only=["person2"])["person2"]
rows = finetune_candidates("cpu", {"first_720": {"frames": TUNE}}, out / "runs",
                           sequences={"person1": person2, "person2": person2})
networks = {"Baseline (pre-trained)": trained_checkpoint("cpu", "baseline", 123),
            "AirPose (pre-trained)": trained_checkpoint("cpu", "airpose", 123),
            "Baseline": out / "runs" / "baseline" / "first_720" / "checkpoints" / "best.pt",
            "AirPose": out / "runs" / "airpose" / "first_720" / "checkpoints" / "best.pt"}
exp = run_recording_experiment("cpu", out / "experiment", networks=networks, sequences={"person2": person2},
                               fine_tune_on="person2", field=True)
clean = run_recording_experiment("cpu")
table = pd.concat([recovery_table(clean, exp, frames={"person2": f}).drop(columns="tuning").assign(frames_of=label)
                   for label, f in (("trained on (0-575)", TRAINED), ("never seen (720-899)", TEST))],
                  ignore_index=True)
kept = {r["network"]: r["kept_step"] for r in rows}
table.insert(2, "kept_step", [kept[n.lower()] for n in table["network"]])
table = table[["frames_of", *[c for c in table.columns if c != "frames_of"]]]
table.to_csv(out / "finetune_same_person.csv", index=False, lineterminator="\n")
(out / "finetune_same_person.md").write_text(
    "Fine-tuning on the field person 2's first 720 frames (selection on 576-719): the share of the field rise "
    "taken back on the frames it trained on and on its last 180 frames, which it never saw; 95 % block-bootstrap "
    "intervals over 1 s blocks (profile 'cpu').\n\n" + markdown_table(table, digits=4))
print(table.round(4).to_string())
