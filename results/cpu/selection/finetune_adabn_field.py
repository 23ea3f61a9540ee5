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
    from airpose_lib.experiments.recordings import finetune_candidates

    rows = finetune_candidates("cpu", {f"adapt_bn_{share}": {"adapt_bn": share} for share in SHARES}, out)
    rows = [{"network": r["network"], "adapt_bn": float(r.pop("candidate")[len("adapt_bn_"):]),
             **{k: v for k, v in r.items() if k != "network"}} for r in rows]
    with open(out / "finetune_adabn_field.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
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
