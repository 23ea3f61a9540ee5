"""What a researcher relies on: one runs folder, profile defaults for notebooks run by
hand, throttled progress off a terminal, validated ``--set``, figure footers, camera frustums."""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

from airpose_lib import cli, paths
from airpose_lib.cli.common import parse_sets
from airpose_lib.paths import RunFolders
from airpose_lib.progress import LOG_INTERVAL_S, progress_bar
from airpose_lib.reproduce import notebook_defaults

REPO = Path(__file__).resolve().parents[1]


# -- one runs folder --------------------------------------------------------------------------------
def test_runs_root_does_not_depend_on_the_working_directory(monkeypatch, tmp_path):

    monkeypatch.delenv(paths.RUNS_ENV, raising=False)
    monkeypatch.chdir(tmp_path)  # e.g. notebooks/, the kernel's folder in JupyterLab
    assert paths.runs_root() == REPO / "runs"
    assert RunFolders.of("cpu").train("airpose", 123) == REPO / "runs" / "train" / "cpu" / "airpose" / "seed123"
    assert RunFolders.of("smoke").recordings() == REPO / "runs" / "recordings" / "smoke"
    monkeypatch.setenv(paths.RUNS_ENV, str(tmp_path / "elsewhere"))
    assert RunFolders.of("cpu").train("airpose", 123) == tmp_path / "elsewhere" / "train" / "cpu" / "airpose" / "seed123"
    assert paths.figures_root() == REPO / "figures"


def test_notebook_defaults_fill_none_from_the_profile(monkeypatch, tmp_path):
    monkeypatch.setenv(paths.RUNS_ENV, str(tmp_path))
    p = notebook_defaults("02_ablation_table", "cpu", seeds=None, train_workers=None, n_qualitative=5)
    assert p.seeds == [123, 124, 125] and p.train_workers == 2  # from profiles/cpu.yaml
    assert p.n_qualitative == 5  # a value given by hand wins
    assert p.output_dir == tmp_path / "cpu" / "02_ablation_table" and p.output_dir.is_dir()
    q = notebook_defaults("02_ablation_table", "smoke", tmp_path / "mine", train_workers=None)
    assert q.output_dir == tmp_path / "mine" and q.train_workers is None  # smoke does not set it


# -- progress ----------------------------------------------------------------------------------------
def test_progress_off_a_terminal_writes_a_line_every_few_seconds(monkeypatch):
    monkeypatch.delenv("AIRPOSE_PROGRESS", raising=False)
    log = io.StringIO()  # not a terminal
    monkeypatch.setattr("sys.stderr", log)
    bar = progress_bar(total=5000, desc="train")
    assert bar.mininterval == LOG_INTERVAL_S
    for _ in range(5000):
        bar.update(1)
    bar.close()
    assert "\r" not in log.getvalue()  # a log file gets one line per redraw, not all on one line
    redraws = [s for s in log.getvalue().split("\n") if s.strip()]
    assert 1 <= len(redraws) <= 3, redraws  # start and end, not one per step
    assert "5000/5000" in redraws[-1]


def test_progress_can_be_switched_off(monkeypatch):
    monkeypatch.setenv("AIRPOSE_PROGRESS", "off")
    assert progress_bar(range(3), desc="x").disable
    monkeypatch.setenv("AIRPOSE_PROGRESS", "auto")
    assert progress_bar(range(3), enabled=False).disable


# -- --set validation -----------------------------------------------------------------------------
@pytest.mark.parametrize("item, message", [
    ("lr=abc", "--set lr=abc: expected float, got 'abc'"),
    ("steps=1.5", "--set steps=1.5: expected int"),
    ("loss.vertex_subsampel=100", "unknown key 'vertex_subsampel' of loss; did you mean 'vertex_subsample'?"),
    ("stepz=3", "unknown key 'stepz' of TrainConfig; did you mean 'steps'?"),
    ("lr.x=1", "'lr' is not a dict option"),
])
def test_train_set_errors_are_one_line(item, message, capsys):
    assert cli.main(["train", "--variant", "airpose", "--set", item]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_set_values_are_typed():
    from airpose_lib.config_fields import field_types
    from airpose_lib.losses import LossConfig
    from airpose_lib.train import TrainConfig

    got = parse_sets(["lr=1e-4", "steps=3", "grad_clip=null", "loss.w_V=10", "model.dropout=0"],
                          TrainConfig, {"loss": field_types(LossConfig)})
    assert got == {"lr": 1e-4, "steps": 3, "grad_clip": None, "loss": {"w_V": 10.0}, "model": {"dropout": 0}}
    assert isinstance(got["loss"]["w_V"], float)


def test_long_commands_share_the_smoke_default_and_quiet():
    parser = cli.build_parser()
    base = {"train": ["--variant", "airpose"], "fit": ["--sequence", "s", "--init", "i"],
            "finetune": ["--checkpoint", "c", "--sequence", "s", "--out", "o"], "reproduce": [],
            "data generate": [], "data sequence": [], "prior train": []}
    for command, extra in base.items():
        args = parser.parse_args([*command.split(), *extra, "--quiet"])
        assert args.profile == "smoke", command
        assert args.quiet, command


# -- figures -------------------------------------------------------------------------------------------
def test_save_figure_names_profile_and_data(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from airpose_lib.viz.style import figure_footer, save_figure

    params = {"notebook": "03_trajectories", "profile": "cpu", "data_source": "official"}
    assert figure_footer(params).startswith("03_trajectories \u00b7 profile cpu \u00b7 data official")
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = save_figure(fig, tmp_path / "f.png", params=params, show=False, close=False)
    assert any(t.get_text() == figure_footer(params) for t in fig.texts)
    assert json.loads(Image.open(path).info["Description"])["profile"] == "cpu"
    plt.close(fig)


def test_camera_frustum_corners_project_to_the_image_corners():
    from airpose_lib.viz.scene3d import camera_frustum

    K = np.array([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]])
    angle = 0.4
    R = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    t = np.array([0.5, -2.0, 9.0])
    pts, lines = camera_frustum(K, (1920, 1080), R, t, depth=2.0)
    assert np.allclose(pts[0], -R.T @ t)  # the optical centre
    cam = pts @ R.T + t  # back into the camera frame: X_c = R X_w + t
    uv = cam[1:, :2] / cam[1:, 2:]
    uv = uv * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    assert np.allclose(uv, [[0, 0], [1920, 0], [1920, 1080], [0, 1080]])
    assert np.allclose(cam[1:, 2], 2.0) and lines.shape == (8, 2)


def test_detections_grid_keeps_its_title():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from airpose_lib.viz.sequences import plot_detections_grid

    img = np.zeros((40, 40, 3), np.uint8)
    det = np.zeros((2, 2, 25, 3))
    det[..., :2], det[..., 2] = 20.0, 1.0
    fig = plot_detections_grid([[img, img], [img, img]], {"openpose": det}, frame_labels=["a", "b"],
                               title="person2: detections")
    assert fig._suptitle.get_text() == "person2: detections"
    plt.close(fig)


def test_online_figures_draw_from_node_records(tmp_path):
    """The notebook-06 figures from stand-in node records (the real ones need drone processes)."""
    import types

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from airpose_lib.runtime import results as R
    from airpose_lib.viz.online import (
        SLOT_STATES,
        plot_fault_states,
        plot_latency,
        plot_online_vs_offline,
        plot_timeline,
        slot_states,
    )

    class Node(types.SimpleNamespace):
        def __len__(self):
            return len(self.frames["target"])

    def node(view: int, n: int = 12) -> Node:
        marks = {f"marks_{k}": np.full(n, 0.01 * (i + 1)) for i, k in enumerate(
            ("wake", "captured", "acquired", "stage1_start", "stage1_end", "stage2_start", "stage2_end",
             "stage3_start", "stage3_end"))}
        frames = {"target": np.arange(n) * 0.24, "latency": np.full(n, 0.12), "slot": np.arange(n),
                  "flags": np.array([0, R.FALLBACK_S2, R.NO_PEERS, R.INVALID] * (n // 4)), **marks}
        valid = np.ones(n, bool)
        valid[3] = False
        return Node(frames=frames, valid=valid, meta={"view": view, "drone": view + 1})

    res = [node(v) for v in range(2)]
    states = slot_states(res[0].frames, 14, R)
    assert list(states[:4]) == [0, 1, 2, 3] and states[-1] == len(SLOT_STATES) - 1  # no record: not running
    figs = [plot_timeline(res, res), plot_latency({"fixed": res, "pipelined": res}, {"fixed": 4.1, "pipelined": 9.0}),
            plot_online_vs_offline(np.tile(np.arange(12)[:, None], (1, 2)), np.ones((12, 2, 3)), np.ones((12, 2, 3))),
            plot_fault_states(np.stack([states, states]), 0.05, "20 % loss")]
    labels = figs[1].axes[1].get_legend_handles_labels()[1]
    assert any("4.17 fps" in lab for lab in labels)  # the window line is in the legend
    rate = figs[1].axes[1]
    figs[1].canvas.draw()
    renderer = figs[1].canvas.get_renderer()
    legend = rate.get_legend().get_window_extent(renderer)
    covered = [a for a in [*rate.patches, *rate.texts] if legend.overlaps(a.get_window_extent(renderer))]
    assert not covered  # the legend sits above the tallest bar (the paper's 20 fps) and its value
    for f in figs:
        f.savefig(tmp_path / "f.png")
        plt.close(f)
