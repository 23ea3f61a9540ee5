"""Issue 31, a measurement (no choice): fine-tuning on a field person 1 recording as long as the
paper's tuning set, against the cpu profile's 30 s.

    AIRPOSE_RUNS=RUNS python results/cpu/selection/tuning_paper_span.py OUT [render|all]

The paper fine-tunes on 7,000 frames of its person 1 (233 s of 30 fps video); the cpu profile's
person 1 is 900 frames (30 s). `cpu_tuning_paper_span.yaml` gives person 1 the paper's span:
the same person, seed and flights over 233 s, every fifth video frame kept (1,400 frames at
6 fps, `video_fps: 30`: the motion blur and the detectors' correlation are those of the video).

1. renders that field recording (`render` stops here);
2. the cpu profile's clean and field experiments (the committed reference's setting: the 900-frame
   person 1), on this machine;
3. the cpu profile's field experiment again with the long recording as the tuning recording and
   the cpu field person 2 as the test: the same networks, fine-tuning settings, prior and test
   frames; only what the networks are tuned on differs;
4. writes OUT/tuning_paper_span_recovery.{csv,md}: for both tuning recordings, the share of
   person 2's field rise that fine-tuning takes back (`recording_tables.recovery_table`), and
   OUT/tuning_paper_span_transfer.{csv,md} (the test person's errors per checkpoint, as
   `field_finetune_transfer.csv`).

One thread; recordings, networks and fine-tuning runs are cached, a rerun resumes."""
import sys
from pathlib import Path

import pandas as pd

from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.experiments.recording_tables import markdown_table, recovery_table, transfer_table
from airpose_lib.experiments.recordings import default_experiment_dir, run_recording_experiment

SPAN = str(Path(__file__).with_name("cpu_tuning_paper_span.yaml"))
out, what = Path(sys.argv[1]), (sys.argv[2] if len(sys.argv) > 2 else "all")
out.mkdir(parents=True, exist_ok=True)
long_person1 = ensure_sequences(SPAN, field=True, only=["person1"], progress=True)["person1"]
if what == "render":
    sys.exit(0)
field = run_recording_experiment("cpu", progress=True, field=True)
clean = run_recording_experiment("cpu", progress=True)
test = ensure_sequences("cpu", field=True)["person2"]
span = run_recording_experiment("cpu", default_experiment_dir(SPAN, field=True), progress=True, field=True,
                                sequences={"person1": long_person1, "person2": test})
labels = {"900 frames, 30 s (cpu)": field, "1,400 frames at 6 fps, 233 s (the paper's span)": span}
recovery = pd.concat([recovery_table(clean, exp).assign(tuning_recording=label) for label, exp in labels.items()],
                     ignore_index=True)
recovery = recovery[~recovery["tuning"]].drop(columns="tuning")
transfer = pd.concat([transfer_table(exp).assign(tuning_recording=label) for label, exp in labels.items()],
                     ignore_index=True)
for name, table, text in (
        ("recovery", recovery, "The share of the field person 2's MPJPE rise (pre-trained, field against clean) "
                               "that fine-tuning on the field person 1 takes back, for two tuning recordings of "
                               "person 1; 95 % block-bootstrap intervals over 1 s blocks of person 2"),
        ("transfer", transfer, "Fine-tuning on the field person 1, the field person 2's errors before and after, "
                               "for two tuning recordings of person 1")):
    cols = ["tuning_recording", *[c for c in table.columns if c != "tuning_recording"]]
    table[cols].to_csv(out / f"tuning_paper_span_{name}.csv", index=False, lineterminator="\n")
    (out / f"tuning_paper_span_{name}.md").write_text(f"{text}.\n\n" + markdown_table(table[cols], digits=4))
    print(table[cols].round(4).to_string())
