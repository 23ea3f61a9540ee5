"""Issue 31 selection: field fine-tuning with the backbone's BatchNorm statistics moved towards
those of person 1's training frames (adapt_bn: the recording's share, 1 = AdaBN) against the
paper's fixed statistics (0), AirPose and Baseline, chosen on person 1's held-out frames (the
selection rule's held-out 2D error at the kept step); person 2's errors per checkpoint logged as
the diagnostic (never used for the choice).

    AIRPOSE_RUNS=<the profile's runs> python results/cpu/selection/finetune_adabn_field.py OUT

(one thread; finished runs in OUT are reused) writes OUT/finetune_adabn_field.csv: per network
and share, the step the selection rule kept, person 1's held-out 2D error there and before
fine-tuning (step 0: the statistics' change alone), and the field person 2's MPJPE before
fine-tuning and at the kept step; then prints the choice. With ``--choose CSV`` only the choice
is made, from that table.

The rule, fixed before the last runs ended: the share with the lowest geometric mean, over the two
networks, of ``heldout_j2d_kept / heldout_j2d_kept(share 0)``; it replaces the paper's 0 only if
that mean is below 0.95 (a 5 % lower held-out 2D error)."""
import csv
import math
import sys
from pathlib import Path

SHARES = (0.0, 0.25, 0.5, 1.0)  # the recording's share of the BatchNorm statistics; 0: the paper's
MARGIN = 0.95


def measure(out: Path) -> list[dict]:
    import dataclasses

    from airpose_lib.data.sequences import ensure_sequences
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.experiments.recordings import _finetune_logged, _tests_key, recording_prior, trained_checkpoint
    from airpose_lib.finetune.config import finetune_config
    from airpose_lib.train import load_train_config

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
        for share in SHARES:
            run = out / variant / f"adapt_bn_{share}"
            _, info = _finetune_logged(pre, tuning, tests, dataclasses.replace(base, adapt_bn=share), run, prior,
                                       False, key)
            log = {int(r["step"]): r for r in csv.DictReader(open(run / "selection.csv"))}
            kept = int(info["selected_step"])
            rows.append({"network": variant, "adapt_bn": share, "kept_step": kept,
                         "heldout_j2d_step0": round(float(log[0]["heldout_j2d"]), 2),
                         "heldout_j2d_kept": round(float(info["heldout_j2d"]), 2),
                         "person2_mpjpe_step0_m": round(float(log[0]["diag_person2_mpjpe_m"]), 4),
                         "person2_mpjpe_kept_m": round(float(log[kept]["diag_person2_mpjpe_m"]), 4)})
            print(rows[-1], flush=True)
    with open(out / "finetune_adabn_field.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows


def choose(rows: list[dict]) -> float:
    """The share the rule picks (module docstring); prints each share's geometric mean."""
    j2d = {(r["network"], float(r["adapt_bn"])): float(r["heldout_j2d_kept"]) for r in rows}
    networks = sorted({n for n, _ in j2d})
    score = {s: math.exp(sum(math.log(j2d[n, s] / j2d[n, 0.0]) for n in networks) / len(networks))
             for s in sorted({s for _, s in j2d}) if s > 0}
    for s, g in score.items():
        print(f"adapt_bn {s}: geometric mean of held-out 2D error / share 0's = {g:.3f}")
    best = min(score, key=score.get)
    chosen = best if score[best] < MARGIN else 0.0
    print(f"chosen: adapt_bn {chosen}" + ("" if chosen else f" (the best share, {best}, scores {score[best]:.3f}, "
                                                           f"not below {MARGIN})"))
    return chosen


if __name__ == "__main__":
    if sys.argv[1] == "--choose":
        choose(list(csv.DictReader(open(sys.argv[2]))))
    else:
        choose(measure(Path(sys.argv[1])))
