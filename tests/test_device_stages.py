"""The device of the stages outside the training loop: the one device rule
(:mod:`airpose_lib.devices`), AirPose+ and the prior's training on the asked device with their
results on the CPU, the parallel ablation workers spread over the GPUs, and the device and
precision of each training in the results provenance. Runs on a CPU-only machine; the CUDA
comparisons run where a GPU is visible."""
from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from airpose_lib.body import load_body_model
from airpose_lib.devices import resolve_device, worker_device
from airpose_lib.errors import ConfigError
from airpose_lib.fitting import AirPosePlusConfig, airpose_plus
from airpose_lib.prior import PriorTrainConfig, VPoser, train_prior

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_fitting_airpose_plus import _one_thread, _perturbed, _scene  # noqa: E402, F401 - autouse fixture

from airpose_lib.reproduce.configs import kit_configs

# the modules (their package re-exports functions of the same names)
plus_module = importlib.import_module("airpose_lib.fitting.airpose_plus")
prior_train_module = importlib.import_module("airpose_lib.prior.train")
CUDA = torch.cuda.is_available()
RESULT_TENSORS = ("theta", "v", "beta", "phi", "tau", "R_body_cam", "t_body_cam", "R_12", "t_12", "kept",
                  "frame_confidence")


def _gpus(monkeypatch, count: int) -> None:
    """Pretend this torch sees ``count`` GPUs (0: none)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: count > 0)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: count)


# -- the rule -------------------------------------------------------------------------------------
def test_auto_is_the_process_gpu_when_cuda_is_available_else_the_cpu(monkeypatch):
    _gpus(monkeypatch, 2)
    assert resolve_device("auto") == torch.device("cuda:0")
    assert resolve_device("auto", local_rank=1) == torch.device("cuda:1")
    assert resolve_device("cuda", local_rank=1) == torch.device("cuda:1")
    assert resolve_device("cuda:1") == torch.device("cuda:1")
    assert resolve_device("cpu", local_rank=1) == torch.device("cpu")
    with pytest.raises(ConfigError, match="only 2 GPU"):
        resolve_device("cuda:2")
    _gpus(monkeypatch, 1)  # two processes on one GPU (seen on an H200: "invalid device ordinal" before)
    for device in ("auto", "cuda"):
        with pytest.raises(ConfigError, match="local rank 1 would train on cuda:1, but only 1 GPU"):
            resolve_device(device, local_rank=1)
    from test_train_loop import tiny_config

    from airpose_lib.train.loop import start_training

    # --world-size 2 on one GPU: one line before any process starts (not a CUDA error in rank 1)
    with pytest.raises(ConfigError, match="local rank 1"):
        start_training(tiny_config(world_size=2, device="auto"), "/nonexistent/run")
    _gpus(monkeypatch, 0)
    assert resolve_device("auto", local_rank=1) == torch.device("cpu")
    with pytest.raises(ConfigError, match="--device cpu"):
        resolve_device("cuda")
    with pytest.raises(ConfigError, match="not a device"):
        resolve_device("gpu0")


def test_engine_launch_uses_the_same_rule():
    from airpose_lib.engine import launch

    assert launch.resolve_device is resolve_device


@pytest.mark.parametrize("k,gpus,asked,expected", [
    (0, 2, "auto", "cuda:0"), (1, 2, "auto", "cuda:1"), (2, 2, "auto", "cuda:0"), (5, 4, "cuda", "cuda:1"),
    (1, 1, "auto", "auto"),  # one GPU: every worker on it, as asked
    (1, 0, "auto", "auto"), (3, 0, "cpu", "cpu"),  # no GPU: nothing changes
    (1, 2, "cpu", "cpu"), (1, 2, "cuda:0", "cuda:0"),  # the user's explicit choice stays
])
def test_parallel_workers_are_spread_over_the_visible_gpus(k, gpus, asked, expected):
    assert worker_device(k, gpus, asked) == expected


def test_an_ablation_worker_trains_on_its_own_gpu(monkeypatch):
    """Worker k of the parallel runner passes cuda:(k mod GPUs) to its training; on a CPU-only
    machine it passes nothing (the profile's device)."""
    import airpose_lib.train.ablation as ablation

    asked = []
    monkeypatch.setattr(ablation, "trained_checkpoint", lambda *a, device=None: asked.append(device) or "x.pt")
    monkeypatch.setattr(ablation, "_WORKER_INDEX", 3)
    _gpus(monkeypatch, 2)
    smoke = kit_configs("smoke").train_inputs()
    assert ablation._train_single_thread((smoke, "airpose", 123, None)) == "x.pt"
    _gpus(monkeypatch, 0)
    ablation._train_single_thread((smoke, "airpose", 123, None))
    assert asked == ["cuda:1", None]


# -- AirPose+ -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def problem(open_model_files):
    body = load_body_model("open", dtype=torch.float64)
    kps, K, gt = _scene(body, F=4)
    torch.manual_seed(0)
    return kps, K, _perturbed(gt), VPoser().eval(), body


def _fit(problem, **cfg):
    kps, K, init, prior, body = problem
    return airpose_plus(kps, K, init, prior=prior, body=body, iterations=3, latent_start=1, progress=False, **cfg)


def test_airpose_plus_asks_the_rule_for_its_device_and_answers_on_the_cpu(problem, monkeypatch):
    """The config's device reaches the rule; the default (cpu) and auto without CUDA give the
    same numbers as before; every result tensor and the prior stay on the CPU."""
    asked = []
    monkeypatch.setattr(plus_module, "resolve_device", lambda d, *a: asked.append(d) or resolve_device(d, *a))
    _gpus(monkeypatch, 0)
    ref = _fit(problem)
    auto = _fit(problem, device="auto")
    assert asked == ["cpu", "auto"] and AirPosePlusConfig().device == "cpu"
    for name in RESULT_TENSORS:
        a, b = getattr(ref, name), getattr(auto, name)
        assert a.device.type == "cpu" and b.device.type == "cpu", name
        assert torch.equal(a, b), name
    assert all(p.device.type == "cpu" for p in problem[3].parameters())


@pytest.mark.skipif(CUDA, reason="checks the error of a CPU-only torch")
def test_airpose_plus_on_cuda_without_cuda_is_a_one_line_error(problem):
    with pytest.raises(ConfigError, match="--device cpu"):
        _fit(problem, device="cuda")


@pytest.mark.skipif(not CUDA, reason="needs a CUDA GPU")
def test_airpose_plus_on_cuda_matches_the_cpu(problem):
    ref, gpu = _fit(problem), _fit(problem, device="cuda")
    for name in RESULT_TENSORS:
        assert getattr(gpu, name).device.type == "cpu", name
    torch.testing.assert_close(gpu.theta, ref.theta, atol=1e-3, rtol=0)
    torch.testing.assert_close(gpu.tau, ref.tau, atol=1e-3, rtol=0)
    problem[3].cpu()


# -- the prior ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def corpus():
    from airpose_lib.data.still.poses import sample_body_pose

    return sample_body_pose(np.random.default_rng(0), 300).astype(np.float32)


def test_prior_training_asks_the_rule_and_returns_a_cpu_model(corpus, monkeypatch):
    asked = []
    monkeypatch.setattr(prior_train_module, "resolve_device", lambda d, *a: asked.append(d) or resolve_device(d, *a))
    _gpus(monkeypatch, 0)
    cfg = dict(steps=4, batch_size=32, kl_anneal_steps=2)
    m1, h1 = train_prior(corpus, PriorTrainConfig(**cfg))
    m2, h2 = train_prior(corpus, PriorTrainConfig(**cfg, device="auto"))
    assert asked == ["cpu", "auto"] and h1["config"]["device"] == "cpu" and h2["config"]["device"] == "auto"
    assert h1["loss"] == h2["loss"]
    for (k, a), b in zip(m1.state_dict().items(), m2.state_dict().values(), strict=True):
        assert a.device.type == "cpu" and b.device.type == "cpu" and torch.equal(a, b), k


@pytest.mark.skipif(CUDA, reason="checks the error of a CPU-only torch")
def test_prior_train_on_cuda_without_cuda_is_a_one_line_error(tmp_path, capsys):
    from airpose_lib.cli import main

    assert main(["prior", "train", "--profile", "smoke", "--steps", "2", "--device", "cuda",
                 "--out", str(tmp_path / "p.pt"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--device cpu" in err and not (tmp_path / "p.pt").exists()


@pytest.mark.skipif(not CUDA, reason="needs a CUDA GPU")
def test_prior_training_on_cuda_learns_like_the_cpu(corpus):
    """The same weights and batches on both devices, but the VAE's noise and dropout masks come
    from each device's own generator (measured on an H200 after 4 steps: losses 7 % apart), so the
    runs agree in what they learn, not number for number."""
    cfg = dict(steps=40, batch_size=32, kl_anneal_steps=2, log_every=1)
    m1, h1 = train_prior(corpus, PriorTrainConfig(**cfg))
    m2, h2 = train_prior(corpus, PriorTrainConfig(**cfg, device="cuda"))
    assert all(p.device.type == "cpu" for p in m2.parameters())
    assert h2["loss"][0] == pytest.approx(h1["loss"][0], rel=0.05)  # same start, other noise
    assert h2["loss"][-1] < 0.7 * h2["loss"][0]
    assert h2["loss"][-1] == pytest.approx(h1["loss"][-1], rel=0.25)


# -- provenance -----------------------------------------------------------------------------------
def test_the_provenance_names_each_trainings_device_and_precision(tmp_path):
    from airpose_lib.eval.reference import train_settings

    class Run:
        def __init__(self, folder):
            self.checkpoint = folder / "checkpoints" / "last.pt"

    git = {"commit": "0123abc", "dirty": False}
    for name, result in (("a", {"config": {"device": "cuda:1", "precision": "bf16"}, "git": git}),
                         ("b", {"config": {"device": "cpu"}}), ("c", [])):
        (tmp_path / name / "checkpoints").mkdir(parents=True)
        (tmp_path / name / "result.json").write_text(json.dumps(result))
    runs = {("airpose", 1): Run(tmp_path / "a"), ("baseline", 1): Run(tmp_path / "b"),
            ("fullcam", 1): Run(tmp_path / "c"), ("multiview", 1): Run(tmp_path / "missing")}
    assert train_settings(runs) == {("airpose", 1): {"device": "cuda:1", "precision": "bf16", "git": git},
                                    ("baseline", 1): {"device": "cpu", "precision": None, "git": None},
                                    ("fullcam", 1): {"device": None, "precision": None, "git": None},
                                    ("multiview", 1): {"device": None, "precision": None, "git": None}}


def test_notebook_02s_bundle_records_the_trainings_device_and_precision(tmp_path):
    from test_eval_reference import VARIANTS, _references, _runs

    from airpose_lib.eval.ablation import ablation_table
    from airpose_lib.eval.significance import claims_table
    from airpose_lib.experiments.ablation import AblationExperiment, write_ablation_bundle
    from airpose_lib.train.ablation import AblationRun

    tables = _runs(seeds=(1,))
    runs = {}
    for (variant, seed), per_view in tables.items():
        folder = tmp_path / "runs" / variant
        (folder / "checkpoints").mkdir(parents=True)
        (folder / "result.json").write_text(json.dumps({"wall_s": 2.0, "config": {"device": "cuda:0",
                                                                                  "precision": "bf16"},
                                                        "git": {"commit": "0123abc", "dirty": False}}))
        runs[variant, seed] = AblationRun(variant, seed, folder / "checkpoints" / "last.pt", {"per_view": per_view})
    exp = AblationExperiment("smoke", "generated", list(VARIANTS), [1], runs, test=None)
    out = write_ablation_bundle(exp, tmp_path / "bundle", table=ablation_table(exp.per_view, references=_references()),
                                claims=claims_table(exp.per_view, n_resamples=50), references=_references())
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["training"] == {f"{v} seed 1": {"device": "cuda:0", "precision": "bf16",
                                                "git": {"commit": "0123abc", "dirty": False}} for v in VARIANTS}
    assert prov["wall_s"]["train airpose seed 1"] == 2.0
