"""Issue 31, a measurement (no choice): the field recordings rendered without their ArUco markers,
everything else as the cpu profile's field recordings, to split the field person 2's rise into
what the markers make and the rest, and to run the fine-tuning's positive control on the rest.

    AIRPOSE_RUNS=RUNS python results/cpu/selection/field_without_markers.py PROFILE OUT

PROFILE is `results/cpu/selection/cpu_field_nomarkers.yaml` (`inherits: cpu`,
`sequences: field_markers: null`). Writes OUT/field_without_markers_gap.{csv,md} (each network on
these field recordings against the clean ones, as `field_gap.csv`) and
OUT/field_without_markers_transfer.{csv,md} (fine-tuning on the field person 1, person 2's errors,
as `field_finetune_transfer.csv`). One thread; the recordings, networks and fine-tuning runs are
cached, a rerun resumes."""
import sys
from pathlib import Path

from airpose_lib.experiments.recording_tables import field_gap_table, markdown_table, transfer_table
from airpose_lib.experiments.recordings import run_recording_experiment

profile, out = sys.argv[1], Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
field = run_recording_experiment(profile, progress=True, field=True)
clean = run_recording_experiment(profile, progress=True)
for name, table, what in (
        ("gap", field_gap_table(clean, field), "Each network on the field recordings without markers against the "
                                               "clean ones, same frames; 95 % block-bootstrap intervals over 1 s blocks"),
        ("transfer", transfer_table(field), "Fine-tuning on the field person 1 (no markers), the field test person's "
                                            "errors before and after")):
    table.to_csv(out / f"field_without_markers_{name}.csv", index=False, lineterminator="\n")
    (out / f"field_without_markers_{name}.md").write_text(f"{what} (profile '{Path(profile).stem}').\n\n"
                                                          + markdown_table(table, digits=4))
    print(table.round(4).to_string())
