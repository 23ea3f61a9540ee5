"""ONNX export of the drone stages, run with ONNX Runtime, against the torch staged run."""
from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("onnxruntime")
onnx = pytest.importorskip("onnx")

from airpose_lib.model import DroneNode, build_model  # noqa: E402
from airpose_lib.model.onnx_export import OnnxDroneNode, export_onnx  # noqa: E402

S = 64


@pytest.mark.parametrize("variant", ["airpose", "baseline"])
def test_onnx_stages_match_torch(tmp_path, variant):
    torch.manual_seed(0)
    model = build_model(variant, "resnet18").eval()
    # non-trivial BatchNorm statistics, so a wrong eval/train export would show
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
            m.running_var.uniform_(0.5, 1.5)
    paths = export_onnx(model, tmp_path, input_size=S)
    for key in ("stage1", "stage_next"):
        onnx.checker.check_model(str(paths[key]))

    g = torch.Generator().manual_seed(1)
    images = torch.randn(2, 3, S, S, generator=g)
    P = torch.tensor([[0.1, -0.2, 0.8], [-0.3, 0.1, 1.4]])
    ref = [DroneNode(model), DroneNode(model)]
    ort = [OnnxDroneNode(tmp_path, num_threads=1), OnnxDroneNode(tmp_path, num_threads=1)]
    msg_ref = [ref[v].stage1(images[v], P[v]) for v in range(2)]
    msg_ort = [ort[v].stage1(images[v : v + 1].numpy(), P[v : v + 1].numpy()) for v in range(2)]
    for k in (2, 3):
        np.testing.assert_allclose(np.stack(msg_ort), np.stack(msg_ref), rtol=0, atol=1e-4)
        msg_ref = [ref[v].stage(k, [msg_ref[1 - v]]) for v in range(2)]
        msg_ort = [ort[v].stage(k, [msg_ort[1 - v]]) for v in range(2)]
    for v in range(2):
        a, b = ort[v].result(), ref[v].result()
        assert set(a) == set(b)
        for key in ("phi6d", "theta6d", "beta", "tau" if variant == "airpose" else "cam"):
            assert a[key].shape == b[key].shape
            torch.testing.assert_close(a[key], b[key], rtol=0, atol=1e-4)
        assert a["input_size"] == S
    # the exchange matters in ONNX too: without messages view 0 ends elsewhere (AirPose only)
    if variant == "airpose":
        lone = OnnxDroneNode(tmp_path, num_threads=1)
        lone.stage1(images[:1].numpy(), P[:1].numpy())
        lone.stage(2, [])
        lone.stage(3, [])
        assert np.abs(lone.result()["theta6d"].numpy() - ort[0].result()["theta6d"].numpy()).max() > 1e-6
