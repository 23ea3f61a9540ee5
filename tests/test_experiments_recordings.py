"""The real-data experiment (airpose_lib.experiments.recordings) on the official real-data
formats with official-format networks: what a user with the official assets runs."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from airpose_lib.paths import RunFolders
from airpose_lib.reproduce.configs import kit_configs


@pytest.fixture(scope="module")
def official(module_tmp, open_model_files):
    from official_fixtures import write_official_real_fixture

    from airpose_lib.experiments.recording_inputs import OFFICIAL_REAL_CHECKPOINTS
    from airpose_lib.model import build_model, write_official_checkpoint
    from airpose_lib.train.official import OFFICIAL_CHECKPOINT_FOLDERS

    root = module_tmp("official")
    write_official_real_fixture(root / "real", frames=[0, 1, 2, 8000, 8001, 8002], image_size=(192, 108))
    folders = {"baseline": [OFFICIAL_CHECKPOINT_FOLDERS["baseline"], OFFICIAL_REAL_CHECKPOINTS["Baseline"]],
               "airpose": [OFFICIAL_CHECKPOINT_FOLDERS["airpose"], OFFICIAL_REAL_CHECKPOINTS["AirPose"]]}
    for variant, names in folders.items():
        for k, name in enumerate(names):
            torch.manual_seed(k)
            write_official_checkpoint(build_model(variant, backbone="resnet18").eval(),
                                      root / "ckpt" / name / "epoch=1.ckpt")
    return root


def test_official_recordings_and_networks_run_without_training(official, tmp_path):
    from airpose_lib.experiments.recordings import (
        METHODS,
        official_networks,
        official_recordings,
        run_recording_experiment,
    )

    nets = official_networks(official / "ckpt")
    assert nets["AirPose"].parent.name == "copenet_twoview_real_ckpt"
    seqs = official_recordings(official / "real")
    assert [s.frames.tolist() for s in seqs.values()] == [[0, 1, 2], [8000, 8001, 8002]]
    exp = run_recording_experiment(kit_configs("smoke"), tmp_path / "exp", sequences=seqs, networks=nets)
    assert exp.tables.empty and not exp.finetune_info  # no ground truth, nothing fine-tuned
    for person in ("person1", "person2"):
        assert list(exp.estimates[person]) == list(METHODS)
        for est in exp.estimates[person].values():
            assert est["tau"].shape == (3, 2, 3) and np.isfinite(est["tau"]).all()
        assert exp.joints[person]["AirPose+"].shape == (3, 2, 22, 3)
    # the two networks of a method differ: the estimates come from the named checkpoints
    a, b = exp.estimates["person2"]["AirPose"], exp.estimates["person2"]["AirPose (pre-trained)"]
    assert not np.allclose(a["tau"], b["tau"])
    cached = sorted((tmp_path / "exp" / "estimates").rglob("*.npz"))
    stamps = [p.stat().st_mtime_ns for p in cached]
    again = run_recording_experiment(kit_configs("smoke"), tmp_path / "exp", sequences=seqs, networks=nets)
    assert [p.stat().st_mtime_ns for p in cached] == stamps  # every step came from the cache
    np.testing.assert_array_equal(again.estimates["person1"]["AirPose+"]["tau"],
                                  exp.estimates["person1"]["AirPose+"]["tau"])


def test_missing_real_checkpoint_names_the_archive(official, tmp_path):
    import shutil

    from airpose_lib.experiments.recordings import official_networks

    shutil.copytree(official / "ckpt", tmp_path / "ckpt")
    shutil.rmtree(tmp_path / "ckpt" / "hmr_real_ckpt")
    with pytest.raises(FileNotFoundError, match="hmr_real_ckpt.zip"):
        official_networks(tmp_path / "ckpt")


def test_recording_prior_uses_vposer_when_installed(tmp_path, monkeypatch):
    from test_prior_vposer import _write_fake_ckpt

    from airpose_lib.experiments.recordings import recording_prior

    root = tmp_path / "vposer"
    _write_fake_ckpt(root / "V02_05" / "snapshots" / "V02_05_epoch=08_val_loss=0.03.ckpt", seed=1)
    monkeypatch.setenv("AIRPOSE_VPOSER_DIR", str(root))
    prior, info = recording_prior(kit_configs("smoke"))
    assert info["source"] == "vposer" and "VPoser V02_05" in info["message"] and info["file"].endswith(".ckpt")
    monkeypatch.setenv("AIRPOSE_VPOSER_DIR", str(tmp_path / "absent"))
    prior, info = recording_prior(kit_configs("smoke"))
    assert info["source"] == "kit" and "not installed" in info["message"]


def test_transfer_table_reads_the_selection_logs():
    from airpose_lib.experiments.recording_tables import transfer_table
    from airpose_lib.experiments.recordings import CONTROL_LABEL, RecordingExperiment

    def info(targets, selected, mpjpe, heldout):
        return {"targets": targets, "selected_step": selected,
                "selection": {"step": [0, 100, 200], "heldout_j2d": heldout,
                              "diag_person2_mpjpe_m": mpjpe, "diag_person2_j2d_px": [16.0, 19.0, 15.0]}}

    exp = RecordingExperiment("cpu", None, {}, {}, {}, None, {}, finetune_info={
        "AirPose": info("detections", 0, [0.073, 0.080, 0.082], [173.0, 117.0, 119.0]),
        CONTROL_LABEL: info("ground_truth", 200, [0.073, 0.078, 0.070], [219.0, 98.0, 116.0]),
        "Baseline": {"targets": "detections", "selection": {}}})  # no selection log: no row
    t = transfer_table(exp).set_index("network")
    assert list(t.index) == ["AirPose", CONTROL_LABEL] and set(t["test"]) == {"person2"}
    a, c = t.loc["AirPose"], t.loc[CONTROL_LABEL]
    assert (a["test_mpjpe_before_m"], a["test_mpjpe_kept_m"]) == (0.073, 0.073)
    assert (a["test_mpjpe_later_min_m"], a["test_mpjpe_later_max_m"]) == (0.080, 0.082) and not a["helps_test"]
    assert (a["tuning_heldout_j2d_before"], a["tuning_heldout_j2d_best_later"]) == (173.0, 117.0)
    assert c["targets"] == "ground_truth" and c["test_mpjpe_kept_m"] == 0.070 and c["helps_test"]
    assert (c["test_j2d_px_before"], c["test_j2d_px_later_min"]) == (16.0, 15.0)


def test_field_experiment_reads_the_field_recordings_into_its_own_folder(tmp_path, monkeypatch):
    # Plumbing only (the experiment itself is the notebooks'): field=True asks ensure_sequences
    # for the profile's field recordings and caches under <runs>/recordings/<profile>_field.
    from airpose_lib.experiments import recordings as rec

    monkeypatch.setenv("AIRPOSE_RUNS", str(tmp_path))
    asked = []

    class Stop(Exception):
        pass

    def fake_ensure(configs, root, **kw):
        asked.append((configs, root.name))
        raise Stop

    monkeypatch.setattr(rec, "ensure_sequences", fake_ensure)
    assert RunFolders.of("smoke").recordings(True) == RunFolders.of("smoke").recordings().with_name("smoke_field")
    smoke = kit_configs("smoke")
    for field in (False, True):
        with pytest.raises(Stop):
            rec.run_recording_experiment(smoke, field=field)
    assert asked == [(smoke.sequences, "sequences_smoke"), (smoke.field_sequences, "sequences_smoke_field")]
    assert (tmp_path / "recordings" / "smoke_field").is_dir()


def _estimate(tau, joints):
    F, V = tau.shape[:2]
    eye = np.broadcast_to(np.eye(3), (F, V, 3, 3)).copy()
    return {"phi": eye, "tau": tau, "theta": np.broadcast_to(np.eye(3), (F, V, 21, 3, 3)).copy(),
            "beta": np.zeros((F, V, 10)), "valid": np.ones((F, V), bool)}, joints


def _recording_truth(F: int, seed: int, V: int = 2):
    """A recording's ground truth without images: ``tau (F, V, 3)`` about 10 m ahead, pelvis-centred
    joints ``(F, V, 22, 3)`` and a sequence stand-in holding them."""
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    tau = rng.normal(0.0, 1.0, (F, V, 3)) + np.array([0.0, 0.0, 10.0])
    j3d = rng.normal(0.0, 0.3, (F, V, 22, 3))
    j3d -= j3d[:, :, :1]
    gt = {"tau": tau, "phi": np.broadcast_to(np.eye(3), (F, V, 3, 3)).copy(), "j3d_cam": j3d, "fps": 30.0}
    return tau, j3d, SimpleNamespace(ground_truth=gt)


def test_field_gap_table_compares_each_method_with_itself_on_the_clean_frames():
    # Hand case: every field estimate sits 0.3 m deeper than the truth, every clean one 0.1 m, so
    # the field costs exactly 0.2 m of MPE in every frame (interval [0.2, 0.2]); the joints are the
    # truth scaled about the pelvis by 1.1 (field) and 1.05 (clean), so the field's MPJPE is twice
    # the clean one's.
    from airpose_lib.experiments.recording_tables import field_gap_table
    from airpose_lib.experiments.recordings import RecordingExperiment

    F = 60
    tau, j3d, seq = _recording_truth(F, seed=0)

    def experiment(depth, scale):
        est, joints = {}, {}
        for m in ("Baseline (pre-trained)", "AirPose (pre-trained)", "Baseline", "AirPose"):
            est[m], joints[m] = _estimate(tau + np.array([0.0, 0.0, depth]), j3d * scale)
        return RecordingExperiment("smoke", None, {"person2": seq}, {"person2": est}, {"person2": joints}, None, {})

    clean, field = experiment(0.1, 1.05), experiment(0.3, 1.1)
    t = field_gap_table(clean, field).set_index(["method", "metric"])
    assert set(t.index.get_level_values("method")) == {f"{m} [field]" for m in
                                                      ("Baseline (pre-trained)", "AirPose (pre-trained)",
                                                       "Baseline", "AirPose")}
    row = t.loc[("AirPose [field]", "mpe_m")]
    assert row["reference"] == "AirPose [clean]" and row["frames"] == F
    assert np.isclose(row["difference"], 0.2) and np.isclose(row["low"], 0.2) and np.isclose(row["high"], 0.2)
    assert row["verdict"] == "higher"
    mp = t.loc[("Baseline [field]", "mpjpe_m")]
    assert np.isclose(mp["value"], 2 * mp["reference_value"])


def test_recovery_table_measures_the_share_of_the_rise_fine_tuning_takes_back():
    # Hand case: the joints are the truth scaled about the pelvis, so a frame's MPJPE is (s - 1)
    # times that frame's own joint spread a_f. Clean pre-trained s = 1.05, field pre-trained 1.20:
    # the rise is 3 a_f in every frame. AirPose tuned 1.10 recovers 2 a_f (share 2/3 in every
    # resample), Baseline tuned 1.25 loses a_f (-1/3), the last pair's 1.18 recovers 0.4 a_f (0.4 / 3).
    from airpose_lib.experiments.recording_tables import recovery_table
    from airpose_lib.experiments.recordings import RecordingExperiment

    F = 90
    tau, j3d, seq = _recording_truth(F, seed=1)

    def experiment(scales, finetune_info=None):
        est, joints = {}, {}
        for m, s in scales.items():
            est[m], joints[m] = _estimate(tau, j3d * s)
        return RecordingExperiment("smoke", None, {"person1": seq, "person2": seq},
                                   {p: est for p in ("person1", "person2")},
                                   {p: joints for p in ("person1", "person2")}, None, {},
                                   finetune_info=finetune_info or {})

    pre = {"Baseline (pre-trained)": 1.05, "AirPose (pre-trained)": 1.05, "Other (pre-trained)": 1.05}
    clean = experiment({**pre, "Baseline": 1.05, "AirPose": 1.05, "Other": 1.05})
    logged = {"AirPose": {"selection": {"step": [0, 100], "diag_person2_mpjpe_m": [0.1, 0.09]}}}
    field = experiment({**{m: 1.20 for m in pre}, "Baseline": 1.25, "AirPose": 1.10, "Other": 1.18}, logged)
    networks = (("Baseline", "Baseline (pre-trained)"), ("AirPose", "AirPose (pre-trained)"),
                ("Other", "Other (pre-trained)"))
    t = recovery_table(clean, field, networks=networks).set_index(["sequence", "network"])
    assert len(t) == 6 and set(t["frames"]) == {F}
    assert list(t.xs("person1")["tuning"]) == [True] * 3 and list(t.xs("person2")["tuning"]) == [False] * 3
    a, b, o = (t.loc[("person2", n)] for n in ("AirPose", "Baseline", "Other"))
    assert np.isclose(a["field_pre"], 4 * a["clean_pre"]) and np.isclose(a["field_tuned"], 2 * a["clean_pre"])
    assert np.isclose(a["rise"], 3 * a["clean_pre"]) and np.isclose(a["recovered"], 2 * a["clean_pre"])
    for row, share in ((a, 2 / 3), (b, -1 / 3), (o, 0.4 / 3)):
        assert np.isclose(row["share"], share) and np.isclose(row["share_low"], share)
        assert np.isclose(row["share_high"], share)
    assert a["rise_low"] > 0 and a["recovered_low"] > 0 and a["verdict"] == "recovers a third or more"
    assert b["recovered_high"] < 0 and b["verdict"] == "makes it worse"
    assert o["recovered_low"] > 0 and o["verdict"] == "recovers less than a third"
    # no gap to close (the field frames no worse than the clean ones): no share, whatever fine-tuning did
    same = recovery_table(clean, experiment({**pre, "Baseline": 1.02, "AirPose": 1.10, "Other": 1.05}, logged),
                          networks=networks)
    assert (same["verdict"] == "no significant rise").all() and same["share"].isna().all()
    assert np.isclose(same.set_index(["sequence", "network"]).loc[("person2", "AirPose"), "recovered"],
                      -a["clean_pre"])
    part = recovery_table(clean, field, networks=networks, frames={"person2": np.arange(30, 60)})
    assert set(part["sequence"]) == {"person2"} and set(part["frames"]) == {30}
    assert np.allclose(part["share"], [-1 / 3, 2 / 3, 0.4 / 3])


def test_runs_field_follows_the_profile_and_the_data_source():
    from types import SimpleNamespace

    from airpose_lib.errors import ConfigError
    from airpose_lib.experiments.recordings import runs_field

    generated, official = SimpleNamespace(source="generated"), SimpleNamespace(source="official")
    smoke, cpu, paper = (kit_configs(p) for p in ("smoke", "cpu", "paper"))
    assert runs_field(generated, smoke) and runs_field(generated, cpu)
    assert not runs_field(official, smoke) and not runs_field(generated, smoke, False)
    assert not runs_field(generated, paper)  # no field recordings
    with pytest.raises(ConfigError, match="field footage"):
        runs_field(official, smoke, True)
    with pytest.raises(ConfigError, match="paper has none"):
        runs_field(generated, paper, True)


def _rotation_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_marker_table_measures_markers_and_methods_against_both_references():
    # Hand case. Two cameras with known extrinsics see a body; an estimate equal to the truth has
    # no UAV2-in-UAV1 error, one with view 2 pushed 0.5 m along camera 2's z is off by exactly
    # 0.5 m, one with view 1 turned 10 deg about camera 1's z is off by 10 deg and |Rz t - t|. The
    # markers are the true relative pose moved 0.03 m along x; frames 0-4 have no marker pose and
    # a network missed frame 6, so every row is over the other F - 6 frames.
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from airpose_lib.experiments.recording_tables import MARKERS_LABEL, marker_table, uav2_in_uav1
    from airpose_lib.experiments.recordings import RecordingExperiment

    F, V = 40, 2
    rng = np.random.default_rng(3)
    R_cw = Rotation.random(F * V, random_state=4).as_matrix().reshape(F, V, 3, 3)
    t_cw = rng.normal(0.0, 5.0, (F, V, 3))
    phi_w = Rotation.random(F, random_state=5).as_matrix()
    p_w = rng.normal(0.0, 1.0, (F, 3))
    phi = R_cw @ phi_w[:, None]
    tau = np.einsum("fvij,fj->fvi", R_cw, p_w) + t_cw
    gt = {"R_cw": R_cw, "t_cw": t_cw, "phi": phi, "tau": tau}
    R12 = R_cw[:, 0] @ np.swapaxes(R_cw[:, 1], -1, -2)  # x_c1 = R12 x_c2 + t12
    t12 = t_cw[:, 0] - np.einsum("fij,fj->fi", R12, t_cw[:, 1])

    def estimate(phi_e, tau_e):
        return {"phi": phi_e, "tau": tau_e, "valid": np.ones((F, V), bool)}

    pushed = tau.copy()
    pushed[:, 1] += np.array([0.0, 0.0, 0.5])  # 0.5 m along camera 2's own z (tau is in camera 2)
    Rz = _rotation_z(10.0)
    turned_phi, turned_tau = phi.copy(), tau.copy()
    turned_phi[:, 0], turned_tau[:, 0] = Rz @ phi[:, 0], tau[:, 0] @ Rz.T
    est = {m: estimate(phi, tau) for m in ("Baseline (pre-trained)", "Baseline", "AirPose")}
    est["AirPose (pre-trained)"] = estimate(turned_phi, turned_tau)
    est["AirPose+"] = estimate(phi, pushed)
    est["Baseline"]["valid"][6, 1] = False
    valid = np.arange(F) >= 5
    truth = {"R_12": R12, "t_12": t12 + np.array([0.03, 0.0, 0.0]), "valid": valid,
             "count": np.full((F, V), 4), "rms_px": np.full((F, V), 0.4)}
    exp = RecordingExperiment("smoke", None, {"person2": SimpleNamespace(ground_truth=gt)}, {"person2": est}, {},
                              None, {}, markers={"person2": truth})
    t = marker_table(exp).set_index(["method", "reference"])
    assert (t["frames"] == F - 6).all() and np.allclose(t["frames_share"], (F - 6) / F)
    keep = valid & (np.arange(F) != 6)
    mk = t.loc[(MARKERS_LABEL, "generated cameras")]
    assert np.isclose(mk["rel_t_median_m"], 0.03) and mk["rel_rot_median_deg"] < 1e-6
    assert mk["markers_median"] == 4 and np.isclose(mk["rms_median_px"], 0.4)
    assert t.loc[("AirPose", "generated cameras"), "rel_t_median_m"] < 1e-9
    assert np.isclose(t.loc[("AirPose", "markers"), "rel_t_median_m"], 0.03)
    plus = t.loc[("AirPose+", "generated cameras")]
    assert np.isclose(plus["rel_t_median_m"], 0.5) and np.isclose(plus["rel_t_mean_m"], 0.5)
    pre = t.loc[("AirPose (pre-trained)", "generated cameras")]
    expected_t = np.linalg.norm(t12[keep] @ Rz.T - t12[keep], axis=-1)
    assert np.isclose(pre["rel_rot_median_deg"], 10.0) and np.isclose(pre["rel_t_median_m"], np.median(expected_t))
    assert set(t.index) == {(MARKERS_LABEL, "generated cameras")} | {
        (m, r) for m in ("AirPose (pre-trained)", "AirPose", "AirPose+") for r in ("generated cameras", "markers")}
    # the plotted lines: the markers' where they posed both drones, NaN elsewhere
    lines = uav2_in_uav1(exp, "person2")
    assert list(lines) == ["AirPose", "AirPose+", MARKERS_LABEL]
    assert np.isnan(lines[MARKERS_LABEL][:5]).all() and np.allclose(lines[MARKERS_LABEL][5:], truth["t_12"][5:])
    np.testing.assert_allclose(lines["AirPose"], t12, atol=1e-9)
    # no markers: an empty table
    exp.markers = {}
    assert marker_table(exp).empty and MARKERS_LABEL not in uav2_in_uav1(exp, "person2")


def test_official_marker_poses_give_the_relative_camera_reference(official, tmp_path):
    """On the official layout the markers come from its marker-pose files: UAV2 in UAV1 against
    them, computed here by hand from the pickled rvec / tvec (OpenCV's Rodrigues, SciPy's angle)."""
    import pickle

    import cv2
    from scipy.spatial.transform import Rotation

    from airpose_lib.data.official.real import MARKER_POSES_FILE
    from airpose_lib.experiments.recording_tables import marker_table
    from airpose_lib.experiments.recordings import official_networks, official_recordings, run_recording_experiment

    seqs = official_recordings(official / "real")
    exp = run_recording_experiment(kit_configs("smoke"), tmp_path / "exp", sequences=seqs,
                                   networks=official_networks(official / "ckpt"))
    assert sorted(exp.markers) == ["person1", "person2"]
    t = marker_table(exp)
    assert set(t["reference"]) == {"markers"} and len(t) == 2 * 3  # no generated cameras on real data
    files = [pickle.loads((official / "real" / f"machine_{v}" / MARKER_POSES_FILE).read_bytes()) for v in (1, 2)]
    for person, seq in seqs.items():
        pose = [[(cv2.Rodrigues(np.asarray(f[f"{i:06d}"]["0"]["rvec"], float))[0],
                  np.asarray(f[f"{i:06d}"]["0"]["tvec"], float)) for f in files] for i in seq.frames]
        R12 = np.stack([R1 @ R2.T for (R1, _), (R2, _) in pose])
        t12 = np.stack([t1 - (R1 @ R2.T) @ t2 for (R1, t1), (R2, t2) in pose])
        e = exp.estimates[person]["AirPose"]
        Re = e["phi"][:, 0] @ np.swapaxes(e["phi"][:, 1], -1, -2)
        te = e["tau"][:, 0] - np.einsum("fij,fj->fi", Re, e["tau"][:, 1])
        row = t[(t["sequence"] == person) & (t["method"] == "AirPose")].iloc[0]
        assert row["frames"] == 3
        assert np.isclose(row["rel_t_median_m"], np.median(np.linalg.norm(te - t12, axis=-1)))
        angle = Rotation.from_matrix(np.swapaxes(Re, -1, -2) @ R12).magnitude()
        assert np.isclose(row["rel_rot_median_deg"], np.degrees(np.median(angle)), atol=1e-6)
