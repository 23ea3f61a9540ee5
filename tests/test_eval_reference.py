"""Results bundles (results/<profile>/) and the check of a new run against them."""
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from airpose_lib.eval.ablation import ablation_table, per_seed_table
from airpose_lib.eval.mean_body import GENDERED_LABEL, NEUTRAL_LABEL
from airpose_lib.eval.reference import (
    FIELD_RECORDING_FILES,
    MARKER_RECORDING_FILES,
    RECORDING_FILES,
    REFERENCE_FILES,
    RESULTS_ROOT,
    ProvenanceError,
    compare_to_reference,
    git_commit,
    install_recordings_reference,
    machine_description,
    provenance_problems,
    provenance_record,
    read_reference_table,
    recordings_report,
    reference_outputs,
    reference_report,
    require_clean_checkout,
    side_by_side,
    train_wall_s,
    write_reference,
)
from airpose_lib.eval.significance import claims_table

VARIANTS = ("baseline", "multiview", "fullcam", "airpose")


# -- temporary git checkouts ----------------------------------------------------------------------
def _git(root: Path, *args: str) -> str:
    """Run git in ``root`` with a fixed identity and no signing (whatever the user's config)."""
    cmd = ["git", "-c", "user.name=kit test", "-c", "user.email=kit@test", "-c", "commit.gpgsign=false", *args]
    return subprocess.run(cmd, cwd=root, capture_output=True, text=True, check=True).stdout.strip()


def _repo(root: Path, ignore: str = "*\n!.gitignore\n") -> Path:
    """A git checkout at ``root`` with one commit: a .gitignore (default: everything else ignored)."""
    if shutil.which("git") is None:
        pytest.skip("needs git")
    root.mkdir(parents=True, exist_ok=True)
    _git(root, "init", "-q")
    (root / ".gitignore").write_text(ignore)
    _git(root, "add", ".gitignore")
    _git(root, "commit", "-q", "-m", "first")
    return root


def _commit(root: Path, name: str) -> str:
    """Commit a new file ``name`` (force-added past the .gitignore); the new HEAD."""
    (root / name).write_text(name)
    _git(root, "add", "-f", name)
    _git(root, "commit", "-q", "-m", name)
    return _git(root, "rev-parse", "HEAD")


@pytest.fixture
def clean_checkout(tmp_path, monkeypatch):
    """tmp_path as a clean git checkout that ``results/`` belongs to (the kit's RESULTS_ROOT):
    bundles written under it record its commit, and --write-reference may install them."""
    import airpose_lib.eval.reference as reference

    _repo(tmp_path)
    monkeypatch.setattr(reference, "RESULTS_ROOT", tmp_path / "results")
    return tmp_path


def _runs(seeds=(1, 2, 3), shift=0.0, n=40):
    rng = np.random.default_rng(0)
    runs = {}
    for s in seeds:
        for k, v in enumerate(VARIANTS):
            e = 2.0 - 0.4 * k + shift + rng.normal(0, 0.05, size=n)
            runs[v, s] = pd.DataFrame({"method": v, "sample": np.arange(n) // 2, "view": np.arange(n) % 2,
                                       "mpe_m": e, "mpjpe_m": e / 10, "pa_mpjpe_m": e / 20})
    return runs


def _references(n=40):
    z = np.linspace(-0.5, 0.5, n)
    neutral = pd.DataFrame({"method": NEUTRAL_LABEL, "mpe_m": np.abs(z) + 0.1, "err_z_m": z, "reproj_px": 0.0})
    return pd.concat([neutral, neutral.assign(method=GENDERED_LABEL, mpe_m=neutral["mpe_m"] / 2)], ignore_index=True)


def _bundle(tmp_path, runs, name="bundle"):
    per_seed = per_seed_table(runs, wall_s={k: 1.5 for k in runs})
    return write_reference(tmp_path / name, table=ablation_table(runs, references=_references()), per_seed=per_seed,
                           claims=claims_table(runs, n_resamples=200), references=_references(), label="smoke",
                           command="airpose reproduce --profile smoke --only 02_ablation_table",
                           step_wall_s={"train and evaluate": 12.34, "mean-body references": None}, extra={"seeds": [1, 2, 3]})


def test_bundle_has_every_file_and_its_provenance(tmp_path):
    out = _bundle(tmp_path, _runs())
    assert sorted(p.name for p in out.iterdir()) == sorted(REFERENCE_FILES)  # no temporary files left
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["kit_version"] and prov["profile"] == "smoke" and prov["seeds"] == [1, 2, 3]
    assert prov["wall_s"] == {"train and evaluate": 12.3, "mean-body references": None}
    assert set(prov["machine"]) >= {"platform", "cpu", "cores", "ram_gib"} and prov["machine"]["cores"] >= 1
    assert "commit" in prov["git"]
    table = read_reference_table(out)
    assert list(table.index)[:4] == ["Baseline", "Baseline + Multi-view", "Baseline + Fullcam", "AirPose"]
    assert table.loc["Baseline", "MPE paper [m]"] == 0.5
    claims = pd.read_csv(out / "claims.csv", index_col=0)
    assert len(claims) == 6 and (claims["verdict"] == "holds").all()
    references = pd.read_csv(out / "mean_body.csv", index_col="method")
    assert list(references.index) == [NEUTRAL_LABEL, GENDERED_LABEL] and (references["images"] == 40).all()
    assert references.loc[NEUTRAL_LABEL, "abs_err_z_m"] == pytest.approx(20 / 78)  # |z| = 1/78, 3/78 ... 39/78
    assert references.loc[GENDERED_LABEL, "mpe_m"] == pytest.approx(references.loc[NEUTRAL_LABEL, "mpe_m"] / 2)
    assert list(table.index)[4:] == [NEUTRAL_LABEL, GENDERED_LABEL]
    assert len(pd.read_csv(out / "per_seed.csv")) == 12


def test_machine_description_reads_the_cpu_and_memory():
    m = machine_description()
    assert m["cpu"] and m["ram_gib"] > 0


def test_machine_description_names_the_vector_extensions():
    """Read against lscpu's flag list, an independent reader of the same kernel table."""
    lscpu = shutil.which("lscpu")
    if lscpu is None or not Path("/proc/cpuinfo").is_file():
        pytest.skip("needs lscpu and /proc/cpuinfo")
    out = subprocess.run([lscpu], capture_output=True, text=True, check=True,
                         env={**os.environ, "LC_ALL": "C"}).stdout
    flags = set(next(line for line in out.splitlines() if line.startswith("Flags:")).split(":", 1)[1].split())
    m = machine_description()
    assert m["vector_extensions"] == [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_tile") if f in flags]


def test_side_by_side_puts_reference_and_paper_next_to_the_run(tmp_path):
    ref = read_reference_table(_bundle(tmp_path, _runs()))
    new = ablation_table(_runs(shift=0.1))
    t = side_by_side(new, ref)
    assert t.loc["AirPose", "MPE kit [m]"] == pytest.approx(ref.loc["AirPose", "MPE [m]"] + 0.1, abs=0.02)
    assert t.loc["AirPose", "MPE paper [m]"] == 0.15 and "MPJPE reference std [m]" in t
    assert side_by_side(new, None)["MPE reference [m]"].isna().all()
    assert read_reference_table(tmp_path / "nowhere") is None


def test_compare_flags_only_means_that_moved_beyond_the_seed_spread(tmp_path):
    ref = per_seed_table(_runs())
    same = compare_to_reference(per_seed_table(_runs()), ref)
    assert len(same) == 4 * 3 and not same["differs"].any() and (same["difference"] == 0).all()
    # move only AirPose's MPE by 10x the reference spread
    moved = per_seed_table(_runs())
    spread = ref.loc[ref["variant"] == "airpose", "mpe_m"].std(ddof=1)
    moved.loc[moved["variant"] == "airpose", "mpe_m"] += 10 * spread
    cmp = compare_to_reference(moved, ref).set_index(["variant", "metric"])
    assert cmp["differs"].sum() == 1 and cmp.loc[("airpose", "mpe_m"), "differs"]
    assert cmp.loc[("airpose", "mpe_m"), "allowed"] == pytest.approx(spread)
    assert cmp.loc[("airpose", "mpe_m"), "basis"] == "reference std over 3 seeds"


def test_one_reference_seed_uses_the_stated_tolerance():
    ref = per_seed_table(_runs(seeds=(1,)))
    new = ref.copy()
    new["mpe_m"] *= 1.05
    assert not compare_to_reference(new, ref)["differs"].any()
    new["mpe_m"] *= 1.10  # 15.5 % above: beyond the 10 %
    cmp = compare_to_reference(new, ref)
    assert cmp.loc[cmp["metric"] == "mpe_m", "differs"].all()
    assert cmp.loc[cmp["metric"] == "mpjpe_m", "differs"].sum() == 0
    assert (cmp["basis"] == "10% of the reference (one seed)").all()


def test_reproduce_report_compares_and_writes_only_when_asked(tmp_path, clean_checkout):
    root = tmp_path / "results"
    bundle = _bundle(tmp_path, _runs())
    msg = reference_report(bundle, "smoke", root=root)
    assert "none for profile 'smoke'" in msg and not root.exists()  # nothing written without the flag
    msg = reference_report(bundle, "smoke", write=True, command="airpose reproduce --write-reference", root=root)
    assert "wrote" in msg and sorted(p.name for p in (root / "smoke").iterdir()) == sorted(REFERENCE_FILES)
    assert json.loads((root / "smoke" / "provenance.json").read_text())["command"] == \
        "airpose reproduce --write-reference"
    assert "0 differ" in reference_report(bundle, "smoke", root=root)
    before = (root / "smoke" / "per_seed.csv").read_bytes()
    worse = _bundle(tmp_path, _runs(shift=1.0), name="worse")
    msg = reference_report(worse, "smoke", root=root)
    assert "12 differ" in msg and "airpose" in msg and "mpe_m" in msg
    assert (root / "smoke" / "per_seed.csv").read_bytes() == before
    assert reference_report(tmp_path / "no-bundle", "smoke", root=root) == ""
    other = _bundle(tmp_path, _runs(seeds=(1, 2)), name="two-seeds")
    assert "differ in seeds / test images" in reference_report(other, "smoke", root=root)


def test_reproduce_report_says_when_the_reference_came_from_another_cpu(tmp_path, clean_checkout):
    root = tmp_path / "results"
    bundle = _bundle(tmp_path, _runs())
    reference_report(bundle, "smoke", write=True, command="airpose reproduce --write-reference", root=root)
    assert "made on" not in reference_report(bundle, "smoke", root=root)  # the same machine: no note
    prov_path = root / "smoke" / "provenance.json"
    prov = json.loads(prov_path.read_text())
    # a CPU no machine reports: a real model name fails the test on that very machine
    prov["machine"].update(cpu="Test CPU 0 (not a real model)", vector_extensions=["sse2", "avx512_bf16"])
    prov_path.write_text(json.dumps(prov))
    msg = reference_report(bundle, "smoke", root=root)
    assert "reference was made on Test CPU 0 (not a real model) (sse2, avx512_bf16), this run on" in msg
    assert "0 differ" in msg.splitlines()[0]
    prov_path.write_text("{}")  # a record without a machine: nothing to say
    assert "made on" not in reference_report(bundle, "smoke", root=root)


def test_training_wall_time_is_read_from_result_json_when_present(tmp_path):
    class Run:
        def __init__(self, folder):
            self.checkpoint = folder / "checkpoints" / "last.pt"

    (tmp_path / "a" / "checkpoints").mkdir(parents=True)
    (tmp_path / "a" / "result.json").write_text(json.dumps({"wall_s": 42.0}))
    (tmp_path / "b" / "checkpoints").mkdir(parents=True)
    (tmp_path / "b" / "result.json").write_text(json.dumps({"step": 3}))
    assert train_wall_s({("baseline", 1): Run(tmp_path / "a"), ("baseline", 2): Run(tmp_path / "b"),
                         ("airpose", 1): Run(tmp_path / "c")}) == {
        ("baseline", 1): 42.0, ("baseline", 2): None, ("airpose", 1): None}


def test_airpose_reproduce_compares_after_notebook_02_and_writes_only_with_the_flag(tmp_path, monkeypatch, capsys,
                                                                                     clean_checkout):
    import airpose_lib.eval.reference as reference
    import airpose_lib.reproduce as rep
    from airpose_lib import cli
    from airpose_lib.reproduce.runner import NotebookResult, RunReport

    out_dir = tmp_path / "runs" / "smoke" / "02_ablation_table"
    _bundle(out_dir.parent, _runs(), name="02_ablation_table/results")

    def fake_run(profile, **kw):
        r = RunReport(profile="smoke", description="", kit_version="0", kernel_name="python3",
                      started_at="now", run_dir=str(out_dir.parent), figures_dir=str(tmp_path / "figures"))
        r.results = [NotebookResult("02_ablation_table", "02_ablation_table.ipynb", status="ok",
                                    parameters={"output_dir": str(out_dir)})]
        return r

    monkeypatch.setattr(rep, "run_profile", fake_run)
    monkeypatch.setattr(reference, "RESULTS_ROOT", tmp_path / "results")
    assert cli.main(["reproduce", "--only", "02"]) == 0
    assert "none for profile 'smoke'" in capsys.readouterr().out and not (tmp_path / "results").exists()
    assert cli.main(["reproduce", "--only", "02", "--write-reference"]) == 0
    assert "wrote" in capsys.readouterr().out and (tmp_path / "results" / "smoke" / "per_seed.csv").is_file()
    assert cli.main(["reproduce", "--only", "02"]) == 0
    assert "0 differ by more than the reference's seed spread" in capsys.readouterr().out


def test_airpose_reproduce_installs_and_compares_the_recordings_after_notebook_05(tmp_path, monkeypatch, capsys,
                                                                                   clean_checkout):
    import airpose_lib.eval.reference as reference
    import airpose_lib.reproduce as rep
    from airpose_lib import cli
    from airpose_lib.reproduce.runner import NotebookResult, RunReport

    out_dir = tmp_path / "runs" / "cpu" / "05_airpose_plus"
    out_dir.mkdir(parents=True)
    _claims([True, True, False]).to_csv(out_dir / "paper_claims.csv", index=False)
    for name in RECORDING_FILES:
        if not (out_dir / name).exists():
            (out_dir / name).write_text("x\n")
    ran = ["03_trajectories"]  # a run with neither notebook 02 nor 05

    def fake_run(profile, **kw):
        r = RunReport(profile="cpu", description="", kit_version="0", kernel_name="python3",
                      started_at="now", run_dir=str(out_dir.parent), figures_dir=str(tmp_path / "figures"))
        r.results = [NotebookResult(n, f"{n}.ipynb", status="ok", parameters={"output_dir": str(out_dir)})
                     for n in ran]
        return r

    monkeypatch.setattr(rep, "run_profile", fake_run)
    monkeypatch.setattr(reference, "RESULTS_ROOT", tmp_path / "results")
    assert cli.main(["reproduce", "--profile", "cpu", "--only", "03", "--write-reference"]) == 2  # nothing to write
    assert "neither 02_ablation_table nor 05_airpose_plus ran" in capsys.readouterr().err
    ran[:] = ["03_trajectories", "05_airpose_plus"]
    assert cli.main(["reproduce", "--profile", "cpu", "--only", "03", "05", "--write-reference"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert (tmp_path / "results" / "cpu" / "recordings" / "paper_claims.csv").is_file()
    assert cli.main(["reproduce", "--profile", "cpu", "--only", "05"]) == 0
    assert "same verdicts" in capsys.readouterr().out


def _claims(holds):
    return pd.DataFrame({"claim": ["pose", "uav2", "uav2"], "sequence": ["person1", "person1", "person1"],
                         "measure": ["MPJPE m", "t error m", "rot error deg"], "value": [0.05, 1.0, 5.0],
                         "holds": holds})


def test_recordings_reference_installs_and_reports_changed_verdicts(tmp_path, clean_checkout):
    nb = tmp_path / "05_airpose_plus"
    nb.mkdir()
    with pytest.raises(FileNotFoundError, match="paper_claims.csv"):
        install_recordings_reference(nb, "cpu", "cmd", root=tmp_path / "results")
    _claims([True, True, False]).to_csv(nb / "paper_claims.csv", index=False)
    for name in RECORDING_FILES:
        if not (nb / name).exists():
            (nb / name).write_text("x\n")
    dst = install_recordings_reference(nb, "cpu", "airpose reproduce --write-reference", root=tmp_path / "results")
    assert sorted(p.name for p in dst.iterdir()) == sorted([*RECORDING_FILES, "provenance.json"])
    # the optional tables (field recordings, markers) go in when the run made them, out when not
    optional = [*FIELD_RECORDING_FILES, *MARKER_RECORDING_FILES]
    for name in optional:
        (nb / name).write_text("y\n")
    install_recordings_reference(nb, "cpu", "cmd", root=tmp_path / "results")
    assert sorted(p.name for p in dst.iterdir()) == sorted([*RECORDING_FILES, *optional, "provenance.json"])
    for name in MARKER_RECORDING_FILES:
        (nb / name).unlink()
    install_recordings_reference(nb, "cpu", "cmd", root=tmp_path / "results")
    assert sorted(p.name for p in dst.iterdir()) == sorted([*RECORDING_FILES, *FIELD_RECORDING_FILES,
                                                            "provenance.json"])
    assert "same verdicts" in recordings_report(nb, "cpu", root=tmp_path / "results")
    _claims([True, False, False]).to_csv(nb / "paper_claims.csv", index=False)  # one verdict flips
    msg = recordings_report(nb, "cpu", root=tmp_path / "results")
    assert msg.startswith("reference: 1 of 3") and "uav2 (person1): True -> False" in msg


# -- provenance: reference results from a clean commit --------------------------------------------
def test_dirty_means_tracked_changes_or_new_files_never_ignored_ones(tmp_path):
    root = _repo(tmp_path / "repo", ignore="runs/\n")
    head = _git(root, "rev-parse", "HEAD")
    assert git_commit(root) == {"commit": head, "dirty": False} and require_clean_checkout(root)["commit"] == head
    (root / "runs").mkdir()
    (root / "runs" / "out.csv").write_text("ignored")  # a run folder git ignores: still clean
    assert git_commit(root)["dirty"] is False
    (root / "new.py").write_text("x = 1")  # new code, not yet committed: dirty
    assert git_commit(root)["dirty"] is True
    (root / "new.py").unlink()
    (root / ".gitignore").write_text("runs/\nmore/\n")  # a change to a tracked file: dirty
    assert git_commit(root)["dirty"] is True
    with pytest.raises(ProvenanceError, match="changes that are not committed") as e:
        require_clean_checkout(root)
    assert str(root) in str(e.value) and "\n" not in str(e.value)
    assert git_commit(tmp_path / "nowhere") == {"commit": None, "dirty": None}
    _git(root, "checkout", "--", ".gitignore")
    # A reproduction's own outputs, written by its first writer, do not make it dirty for the next
    # ones (seen: notebook 02 wrote results/smoke/, then notebook 05's install refused); an input
    # beside them (the committed backbone) and another profile's results do.
    outputs = reference_outputs("smoke")
    assert "results/smoke/table1.csv" in outputs and "results/smoke/recordings/" in outputs
    (root / "results" / "smoke" / "recordings").mkdir(parents=True)
    (root / "results" / "smoke" / "table1.csv").write_text("new")
    (root / "results" / "smoke" / "recordings" / "paper_claims.csv").write_text("new")
    assert git_commit(root, outputs)["dirty"] is False and git_commit(root)["dirty"] is True
    require_clean_checkout(root, outputs)
    for other in ("results/smoke/pretrained_backbone.pt", "results/cpu/table1.csv"):
        (root / other).parent.mkdir(parents=True, exist_ok=True)
        (root / other).write_text("x")
        assert git_commit(root, outputs)["dirty"] is True, other
        (root / other).unlink()
    (tmp_path / "plain").mkdir()
    with pytest.raises(ProvenanceError, match="not a git checkout"):
        require_clean_checkout(tmp_path / "plain")


def _provenance(path: Path, commit, dirty) -> Path:
    path.write_text(json.dumps({"profile": "cpu", "git": {"commit": commit, "dirty": dirty}}))
    return path


def test_provenance_check_on_hand_made_repositories(tmp_path):
    """main: first - a - b (HEAD); side: first - c. A clean record of a, b or first passes; c (not
    an ancestor), an unknown commit, a dirty or unknown state and a missing file do not."""
    root = _repo(tmp_path / "repo")
    first = _git(root, "rev-parse", "HEAD")
    a = _commit(root, "a")
    _git(root, "checkout", "-q", "-b", "side", first)
    c = _commit(root, "c")
    _git(root, "checkout", "-q", "-")
    b = _commit(root, "b")
    assert _git(root, "rev-parse", "HEAD") == b
    p = tmp_path / "provenance.json"
    for commit in (first, a, b):
        assert provenance_problems(_provenance(p, commit, False), root) == []
    assert provenance_problems(_provenance(p, c, False), root) == [f"its commit {c[:12]} is not an ancestor of HEAD "
                                                                   f"in {root}"]
    (unknown,) = provenance_problems(_provenance(p, "f" * 40, False), root)
    assert unknown.startswith(f"its commit {'f' * 12} is not a commit of the repository at {root}")
    assert provenance_problems(_provenance(p, a, True), root) == ["it was made from a checkout with uncommitted changes"]
    assert provenance_problems(_provenance(p, a, None), root) == ["it does not say whether the checkout was clean"]
    assert provenance_problems(_provenance(p, None, None), root) == [
        "it does not say whether the checkout was clean", "it names no git commit"]
    (missing,) = provenance_problems(tmp_path / "none.json", root)
    assert missing.startswith("no readable provenance")
    # the writer records the same git state the check reads
    out = _bundle(tmp_path, _runs())
    prov = json.loads((out / "provenance.json").read_text())
    assert set(prov["git"]) == {"commit", "dirty"}


def test_write_reference_refuses_a_dirty_checkout_in_one_line(tmp_path, monkeypatch, capsys, clean_checkout):
    import airpose_lib.reproduce as rep
    from airpose_lib import cli

    bundle = _bundle(tmp_path, _runs())  # made from the clean checkout: its provenance passes
    assert provenance_problems(bundle / "provenance.json", clean_checkout) == []
    (clean_checkout / ".gitignore").write_text("*\n")  # now a tracked change
    with pytest.raises(ProvenanceError, match="not committed"):
        reference_report(bundle, "smoke", write=True, root=tmp_path / "results")
    assert not (tmp_path / "results").exists()

    def never(*a, **k):
        raise AssertionError("--write-reference ran the notebooks of a dirty checkout")

    monkeypatch.setattr(rep, "run_profile", never)
    assert cli.main(["reproduce", "--only", "02", "--write-reference"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"airpose: error: {clean_checkout} has changes that are not committed")


def test_write_reference_refuses_a_bundle_made_from_a_dirty_checkout(tmp_path, clean_checkout):
    bundle = _bundle(tmp_path, _runs())
    prov = json.loads((bundle / "provenance.json").read_text())
    prov["git"]["dirty"] = True
    (bundle / "provenance.json").write_text(json.dumps(prov))
    with pytest.raises(ProvenanceError, match="uncommitted changes; reference results must come from a clean commit"):
        reference_report(bundle, "smoke", write=True, root=tmp_path / "results")
    assert not (tmp_path / "results").exists()


# Committed results that predate the clean-commit rule, with why; each must leave this list when
# it is regenerated (the test below fails if a listed bundle is clean).
STALE_REFERENCES: dict[str, str] = {}


def test_committed_reference_results_come_from_clean_commits_of_this_history():
    """Every provenance.json under results/ records a clean commit that is an ancestor of HEAD
    (a bundle listed in STALE_REFERENCES must still be stale: the list cannot outlive it)."""
    repo = RESULTS_ROOT.parent
    if not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    if _git(repo, "rev-parse", "--is-shallow-repository") == "true":
        pytest.skip("a shallow clone lacks the commits the bundles name")
    found = sorted(p.relative_to(repo).as_posix() for p in RESULTS_ROOT.rglob("provenance.json"))
    assert "results/smoke/provenance.json" in found
    for rel in found:
        problems = provenance_problems(repo / rel, repo)
        if rel in STALE_REFERENCES:
            assert problems, f"{rel} is clean now: remove it from STALE_REFERENCES"
        else:
            assert not problems, f"{rel}: {problems}"


def test_provenance_names_an_own_profile_file_by_its_place_in_the_checkout(tmp_path):
    inside = RESULTS_ROOT.parent / "airpose_lib" / "profiles" / "lab" / "cpu_backbone_seed1.yaml"
    assert provenance_record(str(inside), "cmd")["profile"] == "airpose_lib/profiles/lab/cpu_backbone_seed1.yaml"
    outside = tmp_path / "mine.yaml"
    assert provenance_record(str(outside), "cmd")["profile"] == str(outside)
    assert provenance_record("cpu", "cmd")["profile"] == "cpu"
