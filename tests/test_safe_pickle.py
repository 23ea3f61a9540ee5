"""No code runs from a data file: every pickle the kit reads from a user's or the
release's files goes through `airpose_lib.safe_pickle`. Each reader gets a crafted pickle whose
unpickling would create a file; the file must not appear, and the reader must fail with its own
one-line error. The plain-data unpickler must give what `pickle.loads` gives for the types the
release's files hold."""
from __future__ import annotations

import os
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from airpose_lib import cli, safe_pickle


class _Payload:
    """Unpickling this runs ``touch <marker>`` (what an attacker's file would do)."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _crafted(marker: Path, around=None) -> bytes:
    obj = {"000000": _Payload(marker)} if around is None else around(_Payload(marker))
    return pickle.dumps(obj, protocol=2)


@pytest.mark.parametrize("protocol", [0, 2, 4, 5])
def test_plain_data_unpickles_as_pickle_does(protocol):
    rng = np.random.default_rng(0)
    obj = {"000001": rng.normal(size=(1, 25, 3)).astype(np.float32), "k": np.arange(5, dtype=np.int64),
           "s": np.float64(1.25), "i": np.int32(-3), "o": np.array(["a", None], dtype=object),
           "list": [1, 2.5, "x", b"\x00\xff", (1, 2)], "set": {1, 2}, "nested": {"rvec": np.ones(3)},
           "dtype": np.dtype("<f8"), "none": None, "bool": True}
    data = pickle.dumps(obj, protocol=protocol)
    got, want = safe_pickle.loads(data), pickle.loads(data)
    # Same objects, same types, same array bytes: pickled again, both give the same bytes.
    assert pickle.dumps(got, protocol=4) == pickle.dumps(want, protocol=4)
    assert got["000001"].dtype == np.float32 and got["nested"]["rvec"].shape == (3,)


def test_a_global_outside_plain_data_is_refused_before_it_is_called(tmp_path):
    marker = tmp_path / "ran"
    with pytest.raises(safe_pickle.ForbiddenGlobalError, match="system"):
        safe_pickle.loads(_crafted(marker))
    assert not marker.exists()
    # A real class (not a data type) is refused too, even a harmless one.
    with pytest.raises(safe_pickle.ForbiddenGlobalError, match="pathlib"):
        safe_pickle.loads(pickle.dumps(Path("x")))


def _assert_nothing_ran(marker: Path) -> None:
    assert not marker.exists(), "unpickling ran code from the file"


def _crafted_recording(tmp_path: Path) -> tuple[Path, Path]:
    """A two-frame recording whose machine_1/openpose_res.pkl is crafted; (folder, marker file)."""
    from airpose_lib.data.sequences.writer import OfficialLayoutWriter

    seq = tmp_path / "seq"
    w = OfficialLayoutWriter(seq, num_views=2)
    for i in range(2):
        w.write_frame(i, [np.zeros((16, 24, 3), np.uint8)] * 2)
    w.finish(np.array([[[20.0, 0, 12], [0, 20.0, 8], [0, 0, 1]]] * 2),
             {"openpose": np.full((2, 2, 25, 3), 0.5), "alphapose": np.full((2, 2, 18, 3), 0.5)})
    marker = tmp_path / "ran"
    (seq / "machine_1" / "openpose_res.pkl").write_bytes(_crafted(marker))
    return seq, marker


def test_detector_file_of_a_recording_runs_nothing(tmp_path):
    from airpose_lib.data.sequences.layout import SequenceFormatError
    from airpose_lib.data.sequences.reader import load_sequence

    seq, marker = _crafted_recording(tmp_path)
    with pytest.raises(SequenceFormatError, match="openpose_res.pkl"):
        load_sequence(seq)
    _assert_nothing_ran(marker)


def test_predict_on_a_crafted_recording_is_one_line_and_runs_nothing(tmp_path, capsys):
    """A crafted file: `airpose predict --sequence DIR` with a crafted openpose_res.pkl."""
    seq, marker = _crafted_recording(tmp_path)
    ckpt = tmp_path / "ckpt.pt"
    ckpt.write_bytes(b"")  # never reached: the recording is read first or the checkpoint fails
    code = cli.main(["predict", "--checkpoint", str(ckpt), "--sequence", str(seq), "--out",
                     str(tmp_path / "pred.npz")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and err[0].startswith("airpose: error:"), err
    _assert_nothing_ran(marker)


def test_official_synthetic_list_and_sample_files_run_nothing(tmp_path):
    from official_fixtures import write_official_synthetic_fixture

    from airpose_lib.data.official.synthetic import OfficialDataError, official_split_files, read_official_sample

    fx = write_official_synthetic_fixture(tmp_path / "syn", n_subjects=2, n_positions=1)
    marker = tmp_path / "ran"
    sample = fx["files"][0]
    sample.write_bytes(_crafted(marker))
    with pytest.raises(OfficialDataError, match=sample.name):
        read_official_sample(sample)
    _assert_nothing_ran(marker)
    lists = fx["root"] / "dataset" / "train_pkls.pkl"
    lists.write_bytes(_crafted(marker, around=lambda p: [p]))
    with pytest.raises(OfficialDataError, match="train_pkls.pkl"):
        official_split_files(fx["root"], "train")
    _assert_nothing_ran(marker)


def test_official_marker_poses_run_nothing(tmp_path):
    from official_fixtures import write_official_real_fixture

    from airpose_lib.data.official.real import read_marker_poses
    from airpose_lib.data.sequences.layout import SequenceFormatError

    write_official_real_fixture(tmp_path / "real", n_frames=2)
    marker = tmp_path / "ran"
    path = tmp_path / "real" / "machine_1" / "markerposes_corrected_all.pkl"
    path.write_bytes(_crafted(marker))
    with pytest.raises(SequenceFormatError, match="markerposes"):
        read_marker_poses(path, [0, 1])
    _assert_nothing_ran(marker)


def _checkpoint_with_payload(path: Path, marker: Path, state: dict) -> Path:
    torch.save({"state_dict": state, "hyper_parameters": _Payload(marker)}, path)
    return path


def test_vposer_checkpoint_runs_nothing(tmp_path):
    from airpose_lib.prior.checkpoint import vposer_state_dict

    marker = tmp_path / "ran"
    ckpt = _checkpoint_with_payload(tmp_path / "V02_05_epoch=13.ckpt", marker,
                                    {"vp_model.decoder_net.0.weight": torch.ones(2, 3)})
    state = vposer_state_dict(ckpt)
    _assert_nothing_ran(marker)
    assert torch.equal(state["decoder_net.0.weight"], torch.ones(2, 3))


def test_official_checkpoint_runs_nothing(tmp_path):
    from airpose_lib.model.official import read_official_checkpoint

    marker = tmp_path / "ran"
    ckpt = _checkpoint_with_payload(tmp_path / "epoch=1.ckpt", marker, {"model.init_shape": torch.zeros(1, 10)})
    blob = read_official_checkpoint(ckpt)
    _assert_nothing_ran(marker)
    assert torch.equal(blob["state_dict"]["model.init_shape"], torch.zeros(1, 10))
    assert "posix.system" in repr(blob["hyper_parameters"]) or "os.system" in repr(blob["hyper_parameters"])


def test_no_reader_of_the_kit_calls_pickle_load_directly():
    """One home for reading foreign pickles: nothing else in the library unpickles a file."""
    root = Path(__file__).resolve().parents[1] / "airpose_lib"
    offenders = []
    for path in root.rglob("*.py"):
        if path.name == "safe_pickle.py":
            continue
        text = path.read_text()
        for pattern in (r"(?<![\w.])pickle\.loads?\(", r"(?<![\w.])pickle\.Unpickler\(", r"allow_pickle=True",
                        r"weights_only=False\)"):
            if re.search(pattern, text):
                offenders.append(f"{path.relative_to(root)}: {pattern}")
    assert not offenders, offenders
