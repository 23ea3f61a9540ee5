"""int8 stage 1 (airpose_lib.model.quantize, runtime.edge): calibrated on the kit's crops, it
agrees with the float32 torch network on fixed inputs within a stated tolerance, really is int8,
and its cached export is keyed by what made it.

Tolerances (ResNet-18 at 128 px, random weights, the dataset's test crops, which the calibration
did not see): backbone features within 5 % relative L2 error of float32 (measured 1.4 %; a
wrong scale or zero point gives errors of order 100 %), and every output of the three-stage,
two-view run within 0.02 (theta6d, beta: unitless; tau: metres) of float32 (measured: tau
5.8 mm, phi6d / theta6d / beta < 6e-4).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

pytest.importorskip("onnxruntime")
onnx = pytest.importorskip("onnx")

from airpose_lib.model import DroneNode  # noqa: E402
from airpose_lib.model.onnx_export import OnnxDroneNode  # noqa: E402
from airpose_lib.model.quantize import QuantSettings, calibration_digest  # noqa: E402
from airpose_lib.runtime.backends import BackendSpec, build_torch_model  # noqa: E402
from airpose_lib.runtime.edge import calibration_crops, ensure_export, export_key  # noqa: E402
from airpose_lib.runtime.networks import make_stage_model  # noqa: E402

S = 128
SPEC = BackendSpec(kind="onnx-int8", variant="airpose", backbone="resnet18", input_size=S, seed=3)
FEATURE_RTOL = 0.05
OUTPUT_ATOL = 0.02


@pytest.fixture(scope="module")
def tiny_still(module_tmp, open_model_files):
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset

    root = module_tmp("tiny_still")
    generate_still_dataset(GenerationConfig(num_samples=8, shard_size=4, crop_size=32, seed=0), root,
                           workers=1, progress=False, record=False)
    return root


@pytest.fixture(scope="module")
def exported(tiny_still, module_tmp):
    cache = module_tmp("onnx_cache")
    folder = ensure_export(SPEC, calibration_root=tiny_still, calibration_samples=8, root=cache)
    return folder, cache


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_int8_graph_is_quantised_per_channel_in_the_backbone_only(exported, tiny_still):
    folder, _ = exported
    graph = onnx.load(str(folder / "stage1_int8.onnx")).graph
    inits = {i.name: i for i in graph.initializer}
    ops = [n.op_type for n in graph.node]
    assert ops.count("QuantizeLinear") > 10 and "DequantizeLinear" in ops
    conv_weights = 0
    for n in graph.node:
        if n.op_type == "DequantizeLinear" and n.input[0] in inits and inits[n.input[0]].data_type == onnx.TensorProto.INT8:
            scale = onnx.numpy_helper.to_array(inits[n.input[1]])
            assert scale.ndim == 1 and scale.size > 1  # one scale per output channel
            conv_weights += 1
    assert conv_weights == 20  # ResNet-18: 17 + 3 shortcut convolutions
    produced_by = {o: n for n in graph.node for o in n.output}
    for n in graph.node:
        if n.op_type == "Gemm":  # the regressor stays float32: no DequantizeLinear feeds it
            assert all(produced_by.get(i) is None or produced_by[i].op_type != "DequantizeLinear" for i in n.input)
    meta = json.loads((folder / "meta.json").read_text())
    info = meta["stage1"]["int8"]
    images, P = calibration_crops(tiny_still, S, samples=8)
    assert info["settings"] == QuantSettings().to_dict() and info["calibration"]["crops"] == len(images) >= 8
    assert info["calibration"]["sha256"] == calibration_digest(images, P)


def test_int8_agrees_with_float32_on_fixed_inputs(exported, tiny_still):
    folder, _ = exported
    images, P = calibration_crops(tiny_still, S, samples=2, split="test")  # not seen by the calibration
    model = build_torch_model(SPEC)
    ref = [DroneNode(model), DroneNode(model)]
    q = [OnnxDroneNode(folder, num_threads=1, precision="int8") for _ in range(2)]
    for f in range(2):
        x, p = images[2 * f : 2 * f + 2], P[2 * f : 2 * f + 2]
        msg_r = [ref[v].stage1(torch.from_numpy(x[v : v + 1]), torch.from_numpy(p[v : v + 1])) for v in range(2)]
        msg_q = [q[v].stage1(x[v : v + 1], p[v : v + 1]) for v in range(2)]
        for v in range(2):
            feat_r = ref[v]._feat.numpy()
            err = _relative(q[v]._feat, feat_r)
            assert 0 < err < FEATURE_RTOL, err  # > 0: the int8 graph ran, not a float32 copy
        for k in (2, 3):
            msg_r = [ref[v].stage(k, [msg_r[1 - v]]) for v in range(2)]
            msg_q = [q[v].stage(k, [msg_q[1 - v]]) for v in range(2)]
        for v in range(2):
            a, b = q[v].result(), ref[v].result()
            for key in ("phi6d", "theta6d", "beta", "tau"):
                torch.testing.assert_close(a[key], b[key], rtol=0, atol=OUTPUT_ATOL)


def test_backend_kinds_and_the_cache(exported, tiny_still):
    folder, cache = exported
    spec = BackendSpec(**{**SPEC.to_dict(), "onnx_dir": str(folder)})
    assert make_stage_model(spec).precision == "int8"
    assert make_stage_model(BackendSpec(**{**spec.to_dict(), "kind": "onnx"})).precision == "fp32"
    # same network, crops and settings: the folder is reused, not rebuilt
    stamp = (folder / "stage1_int8.onnx").stat().st_mtime_ns
    again = ensure_export(SPEC, calibration_root=tiny_still, calibration_samples=8, root=cache)
    assert again == folder and (folder / "stage1_int8.onnx").stat().st_mtime_ns == stamp
    # the key moves with every ingredient
    images, P = calibration_crops(tiny_still, S, samples=8)
    ident = {"random": {"seed": 3}}
    base = export_key(ident, S, "int8", calibration_digest(images, P), QuantSettings())
    assert base == export_key(ident, S, "int8", calibration_digest(images.copy(), P), QuantSettings())
    assert base != export_key(ident, S, "int8", calibration_digest(images[:-1], P[:-1]), QuantSettings())
    assert base != export_key(ident, S, "int8", calibration_digest(images, P), QuantSettings(per_channel=False))
    assert base != export_key({"random": {"seed": 4}}, S, "int8", calibration_digest(images, P), QuantSettings())
    assert base != export_key(ident, S, "fp32")


def test_fp32_folder_has_no_int8_stage(tmp_path):
    torch.manual_seed(0)
    folder = ensure_export(BackendSpec(kind="onnx", backbone="resnet18", input_size=32), root=tmp_path)
    with pytest.raises(FileNotFoundError, match="airpose export --quantize int8"):
        OnnxDroneNode(folder, precision="int8")


def test_export_command_rejects_bad_paths(tmp_path, capsys):
    from airpose_lib.cli import main

    assert main(["export", "--checkpoint", str(tmp_path / "missing.pt"), "--quantize", "int8"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.pt" in err[0]
    assert main(["export", "--quantize", "int8", "--calibration", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "manifest.yaml" in err[0] and "airpose data generate" in err[0]
