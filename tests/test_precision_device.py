"""Mixed precision and devices: bf16 training steps of every variant and of the
pretraining, every tensor on the run's device, one-line errors for a bad device or fp16 on CPU, and
the RNG restore with another number of GPUs."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from airpose_lib import cli
from airpose_lib.engine import checkpoint as ckpt
from airpose_lib.engine.launch import autocast, check_precision, resolve_device
from airpose_lib.train import default_model_factory, load_checkpoint, train

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_train_loop import FAKES, tiny_config  # noqa: E402

from airpose_lib.reproduce.configs import kit_configs


def _watched(seen: dict):
    """A model factory that records every module output's device and dtype."""
    def factory(cfg):
        model = default_model_factory(cfg)
        seen["model"] = model

        def hook(module, args, out):
            outs = out.values() if isinstance(out, dict) else out if isinstance(out, (tuple, list)) else [out]
            for t in outs:
                if isinstance(t, torch.Tensor):
                    seen.setdefault("outputs", set()).add((t.device, t.dtype))
        for m in model.modules():
            m.register_forward_hook(hook)
        return model
    return factory


VARIANTS = [("baseline", {}), ("multiview", {}), ("fullcam", {}), ("airpose", {}),
            ("pretrain", {"task": "pretrain", "model": {"n_heading_bins": 12}, "loss": {}})]


@pytest.mark.parametrize("variant,extra", VARIANTS, ids=[v for v, _ in VARIANTS])
def test_one_bf16_step_of_every_variant_stays_on_the_device(variant, extra, tmp_path, open_model_files):
    """One step in bf16 and in fp32 from the same seed: finite, the bf16 network really ran in
    bfloat16 (module outputs), the losses in float32, every parameter, buffer, optimiser state and
    output on the run's device, and the two runs close but not equal."""
    states = {}
    for precision in ("fp32", "bf16"):
        seen: dict = {}
        cfg = tiny_config(variant=variant if variant != "pretrain" else "airpose", steps=1, val_every=None,
                          freeze_backbone=False, device="cpu", precision=precision, **extra)
        fakes = FAKES if variant != "pretrain" else {"dataset_factory": FAKES["dataset_factory"]}  # its own loss
        res = train(cfg.variant, config=cfg, out_dir=tmp_path / precision, model_factory=_watched(seen), **fakes)
        assert res.step == 1 and np.isfinite(res.train_loss)
        assert res.config["precision"] == precision and res.config["device"] == "cpu"
        device = torch.device("cpu")
        tensors = list(seen["model"].parameters()) + list(seen["model"].buffers())
        assert tensors and all(t.device == device for t in tensors)
        assert all(d == device for d, _ in seen["outputs"])
        dtypes = {dt for _, dt in seen["outputs"]}
        assert (torch.bfloat16 in dtypes) == (precision == "bf16")
        assert all(p.dtype == torch.float32 for p in seen["model"].parameters())  # master weights
        states[precision] = load_checkpoint(res.checkpoint)
        for s in states[precision]["optimizer"]["state"].values():
            assert all(v.device == device for v in s.values() if isinstance(v, torch.Tensor))
    a, b = states["fp32"]["model"], states["bf16"]["model"]
    weights = [k for k in a if a[k].is_floating_point() and "running_" not in k]  # BatchNorm statistics differ more
    diff = max(float((a[k].double() - b[k].double()).abs().max()) for k in weights)
    assert 0 < diff <= 2 * cfg.lr * 1.001  # one Adam step of ~lr each; bf16 moves some coordinates differently


def test_fp16_on_cpu_and_unknown_precisions_are_refused():
    check_precision("bf16", "cpu")
    with pytest.raises(ValueError, match="fp16 needs a CUDA device"):
        check_precision("fp16", "cpu")
    with pytest.raises(ValueError, match="precision must be"):
        check_precision("fp8", "cpu")
    with autocast("bf16", "cpu"):
        assert torch.nn.functional.linear(torch.ones(2, 3), torch.ones(4, 3)).dtype == torch.bfloat16
    with autocast("fp32", "cpu"):
        assert torch.nn.functional.linear(torch.ones(2, 3), torch.ones(4, 3)).dtype == torch.float32


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the CPU-only torch's message")
def test_a_bad_device_is_a_user_error(capsys, tmp_path):
    with pytest.raises(ValueError, match="CPU-only torch"):
        resolve_device("cuda")
    with pytest.raises(ValueError, match="is not a device"):
        resolve_device("gpu0")
    assert resolve_device("auto") == torch.device("cpu")
    for argv in (["--device", "cuda"], ["--device", "cuda:1"], ["--device", "gpu"], ["--set", "precision=fp16"]):
        code = cli.main(["train", "--variant", "airpose", "--profile", "smoke", "--out", str(tmp_path / "r"),
                         "--quiet", *argv])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.startswith("airpose: error:") and "\n" not in err, (argv, err)


def test_cuda_rng_states_restore_onto_fewer_gpus(monkeypatch):
    """A checkpoint saved with 2 visible GPUs resumes where 1 is visible: GPU 0's state is restored
    (set_rng_state_all would raise)."""
    calls = []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(torch.cuda, "set_rng_state", lambda state, device: calls.append((int(state[0]), device)))
    state = ckpt.capture_rng_state()
    state["cuda"] = [torch.tensor([7], dtype=torch.uint8), torch.tensor([9], dtype=torch.uint8)]
    ckpt.restore_rng_state(state)
    assert calls == [(7, 0)]


def test_evaluation_and_features_take_the_device(tmp_path, open_model_files):
    """`airpose eval` / `predict` default to `auto` (CPU here); a checkpoint recorded on another
    device loads onto the one asked for; a device this machine lacks is a ValueError (one CLI line)."""
    from airpose_lib.model import resnet18
    from airpose_lib.train.evaluate import load_trained_model
    from airpose_lib.train.features import compute_features

    cfg = tiny_config(steps=1, val_every=None, device="cpu")
    res = train("airpose", config=cfg, out_dir=tmp_path / "r", **FAKES)
    state = load_checkpoint(res.checkpoint)
    state["config"]["device"] = "cuda:3"  # as a GPU run records it
    torch.save(state, tmp_path / "gpu.pt")
    model, loaded = load_trained_model(tmp_path / "gpu.pt", "auto")
    auto = "cuda" if torch.cuda.is_available() else "cpu"  # auto: the GPU where there is one
    assert loaded.device == "cuda:3" and all(p.device.type == auto for p in model.parameters())
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CPU-only torch"):
            load_trained_model(tmp_path / "gpu.pt", "cuda")

    class Crops(torch.utils.data.Dataset):
        def __len__(self):
            return 3

        def __getitem__(self, i):
            return {"images": torch.randn(2, 3, 32, 32, generator=torch.Generator().manual_seed(i))}

    net = resnet18().eval()
    a = compute_features(net, Crops(), batch_size=2)
    b = compute_features(net, Crops(), batch_size=2, device="cpu")
    assert a.shape == (3, 2, 512) and np.array_equal(a, b)


@pytest.mark.parametrize("machine, flags, isa, aten, native", [
    ("x86_64", {"avx2", "avx512f", "avx512_bf16"}, None, "AVX512", True),
    ("x86_64", {"avx2", "amx_bf16", "amx_tile"}, None, "AVX512", True),
    ("x86_64", {"avx2", "fma"}, None, "AVX2", False),  # an AVX2-only laptop: emulated bf16
    ("x86_64", {"avx2", "avx512f"}, None, "AVX512", False),  # AVX-512 without its bf16 extension
    ("x86_64", {"avx512_bf16"}, "AVX2", "AVX512", False),  # oneDNN limited below its bf16 kernels
    ("x86_64", {"avx512_bf16"}, "avx512_core_amx", "AVX512", True),  # the limit still includes them
    ("x86_64", {"avx512_bf16"}, None, "AVX2", False),  # ATen limited to its AVX2 kernels
    ("aarch64", {"fp", "asimd", "bf16"}, None, "DEFAULT", True),
    ("aarch64", {"fp", "asimd"}, None, "DEFAULT", False),
])
def test_native_bf16_reads_the_cpu_flags_and_the_kernel_limits(machine, flags, isa, aten, native):
    from airpose_lib.engine.launch import native_bf16

    got, reason = native_bf16(machine, flags, isa, aten)
    assert got is native and reason


def test_auto_precision_is_bf16_only_with_native_bf16(monkeypatch):
    from airpose_lib.engine import launch

    for native, expected in ((True, "bf16"), (False, "fp32")):
        monkeypatch.setattr(launch, "cpu_bf16", lambda n=native: (n, "a CPU"))
        assert launch.resolve_precision("auto", "cpu") == (expected, "auto: a CPU")
    assert launch.resolve_precision("bf16", "cpu") == ("bf16", "set in the config")  # forced either way
    assert launch.resolve_precision("fp32", "cpu")[0] == "fp32"
    with pytest.raises(ValueError, match="precision must be"):
        launch.resolve_precision("fast", "cpu")


def test_auto_precision_under_an_avx2_limit_picks_fp32():
    """The kernel path an AVX2-only machine runs, on whatever CPU runs the test."""
    import subprocess

    env = {**os.environ, "ONEDNN_MAX_CPU_ISA": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"}
    out = subprocess.run([sys.executable, "-c", "from airpose_lib.engine.launch import resolve_precision; "
                          "print(resolve_precision('auto', 'cpu')[0])"], env=env, capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "fp32"


def test_a_backbone_of_auto_precision_is_found_whichever_precision_made_it():
    """The committed cpu backbone was trained in bf16: auto finds it on a CPU that would pick fp32."""
    from airpose_lib.train.pretrain import own_backbone_keys, stage_key_options

    keys = own_backbone_keys(kit_configs("cpu").pretrain)
    committed = json.loads((Path(__file__).resolve().parents[1] / "results/cpu/pretrained_backbone.json").read_text())
    assert committed["key"] in keys and len(keys) == 2
    from airpose_lib.train.pretrain import pretrain_stages

    fixed = [c.replace(precision="fp32") for c in pretrain_stages(kit_configs("cpu").pretrain)]
    assert len(stage_key_options(fixed, "fp")) == 1  # a forced precision has one key
