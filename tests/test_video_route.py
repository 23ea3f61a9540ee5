"""``airpose video`` end to end on known truth: a kit recording, clean and through the field camera
pipeline, exported as two mp4 files (UAV2's started late by a known shift), run through the
command with the shipped networks, and scored against the recording's ground truth next to the
same networks on the recording's own frames; and the command's answers to bad input."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from airpose_lib.data.sequences.config import SequenceConfig
from airpose_lib.data.sequences.presets import field_variant
from airpose_lib.data.sequences.recording import generate_sequence
from airpose_lib.data.video.export import export_videos

N_FRAMES = 150  # 5 s: the offset needs a few seconds of varied motion
N_FIELD = 150  # the field test is given the offset
SHIFT = 7  # UAV2's video starts 7 frames late: the true offset is -7
TOLERANCE = 0.10  # the issue's: the video route within 10 % of the recording route


@pytest.fixture(scope="module")
def networks():
    from airpose_lib.experiments.video import video_networks

    return video_networks("cpu", None, None, None)


def _exported(module_tmp, field: bool):
    config = SequenceConfig(person="person2", n_frames=N_FIELD if field else N_FRAMES, render_scale=0.5, seed=2,
                            anti_aliasing=False)
    if field:
        config = field_variant(config, "dji")
    root = module_tmp("field" if field else "clean")
    generate_sequence(config, root / "recording")
    paths = export_videos(root / "recording", root / "videos", shift=SHIFT)
    return root, paths


@pytest.fixture(scope="module")
def clean(module_tmp):
    return _exported(module_tmp, field=False)


@pytest.fixture(scope="module")
def field(module_tmp):
    return _exported(module_tmp, field=True)


def _run(root, paths, networks, **kw):
    from airpose_lib.experiments.video import VideoConfig, run_video
    from airpose_lib.experiments.video_check import known_truth_table
    from airpose_lib.prior import load_prior

    calib = [str(root / "recording" / f"machine_{v}" / "camera_calib.yml") for v in (1, 2)]
    cfg = VideoConfig(videos=(str(paths["uav1"]), str(paths["uav2"])), out=str(root / "out"), intrinsics=tuple(calib),
                      keypoints=(str(paths["uav1_keypoints"]), str(paths["uav2_keypoints"])), overlays=False, **kw)
    run = run_video(cfg, networks, progress=False)
    table = known_truth_table(run.out, networks.airpose, prior=load_prior("kit", networks.prior))
    return run, table


def _assert_routes_agree(table, n_frames):
    metrics = ["mpjpe_median_m", "uav2_in_uav1_position_median_m", "uav2_in_uav1_orientation_median_deg"]
    video = table[table["route"] == "video"].set_index("method")
    rec = table[table["route"] == "recording"].set_index("method")
    assert set(video.index) == set(rec.index) == {"AirPose", "AirPose+"}
    assert (video["frames"] == n_frames - SHIFT).all()
    ratio = video[metrics] / rec[metrics]
    assert ((ratio - 1).abs() <= TOLERANCE).all().all(), f"video / recording route:\n{ratio}\n{table}"


def test_clean_videos_give_the_recording_routes_errors_and_the_true_offset(clean, networks):
    root, paths = clean
    run, table = _run(root, paths, networks)
    assert abs(run.offset["frames"] - (-SHIFT)) <= 1, run.offset
    _assert_routes_agree(table, N_FRAMES)
    with np.load(run.files["smplx"]) as z:
        assert z["airpose_plus_body_pose"].shape == (N_FRAMES - SHIFT, 2, 63)
        np.testing.assert_array_equal(z["frames_uav2"] - z["frames"], run.offset["frames"])
    csv = run.files["uav2_in_uav1"].read_text().splitlines()
    assert csv[0].startswith("method,frame_uav1,frame_uav2,time_s,x_m") and len(csv) == 1 + 2 * (N_FRAMES - SHIFT)


def test_field_videos_at_the_given_offset_give_the_recording_routes_errors(field, networks):
    root, paths = field
    run, table = _run(root, paths, networks, offset=-SHIFT)
    assert run.offset == {"frames": -SHIFT, "seconds": -SHIFT / 30.0, "estimated": False}
    _assert_routes_agree(table, N_FIELD)


# -- the command ----------------------------------------------------------------------------------
def _airpose(*args, cwd=None):
    args = [*map(str, args)] + ([] if "--quiet" in map(str, args) else ["--quiet"])  # progress bars go to stderr
    return subprocess.run([sys.executable, "-m", "airpose_lib.cli", "video", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=900)


def _one_line_error(res, *needles):
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("airpose: error: "), res.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def test_the_command_writes_overlays_and_resumes_without_redoing_stages(clean, tmp_path):
    root, paths = clean
    out = tmp_path / "run"
    args = [paths["uav1"], paths["uav2"], "--out", out, "--keypoints", paths["uav1_keypoints"],
            paths["uav2_keypoints"], "--offset", -SHIFT, "--end", 20, "--no-fit", "--quiet"]
    res = _airpose(*args)
    assert res.returncode == 0, res.stderr
    assert "no intrinsics given" in res.stdout  # the default camera is announced
    import cv2

    for v in (1, 2):
        cap = cv2.VideoCapture(str(out / f"overlay_uav{v}.mp4"))
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 20 - SHIFT
        cap.release()
    assert (out / "trajectory.png").stat().st_size > 10_000
    stamp = (out / "airpose.npz").stat().st_mtime_ns
    again = _airpose(*args)
    assert again.returncode == 0 and (out / "airpose.npz").stat().st_mtime_ns == stamp  # the network did not rerun


def test_bad_input_is_one_line_naming_the_file(clean, tmp_path):
    root, paths = clean
    kp = ["--keypoints", paths["uav1_keypoints"], paths["uav2_keypoints"]]
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(paths["uav2"].read_bytes()[:4096])
    _one_line_error(_airpose(paths["uav1"], cut, "--out", tmp_path / "a", *kp), "cut.mp4")
    calib = tmp_path / "cams.yaml"
    calib.write_text("fx: 1500\nfy: 1500\ncx: 960\ncy: 540\nwidth: 1920\nheight: 1080\n")
    _one_line_error(_airpose(paths["uav1"], paths["uav2"], "--out", tmp_path / "b", "--intrinsics", calib, *kp),
                    "cams.yaml", "1920x1080", "960x540")
    _one_line_error(_airpose(paths["uav1"], paths["uav2"], "--out", tmp_path / "c", "--offset", 5000, *kp),
                    "--offset 5000", "uav2.mp4")
    assert not (tmp_path / "c" / "airpose.npz").exists()
    nobody = tmp_path / "nobody.pkl"
    nobody.write_bytes(__import__("pickle").dumps({}))
    _one_line_error(_airpose(paths["uav1"], paths["uav2"], "--out", tmp_path / "d", "--keypoints",
                             paths["uav1_keypoints"], nobody), "nobody.pkl", "0 %")
    busy = tmp_path / "busy"
    done = busy / "kept.txt"
    busy.mkdir()
    done.write_text("an earlier result")
    from airpose_lib.folder_lock import folder_lock

    with folder_lock(busy, "output folder"):
        _one_line_error(_airpose(paths["uav1"], paths["uav2"], "--out", busy, *kp), str(busy))
    assert done.read_text() == "an earlier result"
