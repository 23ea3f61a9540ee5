"""Asset manifests, locate, verify, fetch (against a loopback HTTP server) and the data-source choice.

Nothing here touches the network beyond 127.0.0.1 or writes outside tmp_path: the kit cache, the
config folder and every asset variable point into tmp_path.
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import http.server
import io
import tarfile
import threading
from pathlib import Path

import pytest
import yaml

from airpose_lib.assets import (
    CHECKSUM_MISMATCH,
    MISSING,
    PRESENT,
    SIZE_MISMATCH,
    AssetError,
    ChecksumError,
    FetchError,
    ManifestError,
    RegistrationRequired,
    fetch,
    list_manifests,
    load_asset_manifest,
    locate,
    read_manifest,
    resolve_data_source,
    verify,
)
from airpose_lib.assets.manifest import manifest_dir
from airpose_lib.cli.assets import add_asset_commands

REPO_MANIFESTS = Path(__file__).resolve().parents[1] / "data_manifests"
OFFICIAL = ("official_synthetic", "official_real", "official_checkpoints", "smplx_v1_1", "vposer_v02_05")
ASSET_ENV = ("AIRPOSE_OFFICIAL_SYNTHETIC_DIR", "AIRPOSE_OFFICIAL_REAL_DIR", "AIRPOSE_OFFICIAL_CHECKPOINTS_DIR",
             "AIRPOSE_SMPLX_DIR", "AIRPOSE_VPOSER_DIR", "AIRPOSE_TOY_DIR", "AIRPOSE_ASSETS_CONFIG")


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    """Cache, config and asset folders inside tmp_path; loopback never goes through a proxy."""
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    for var in ASSET_ENV:
        monkeypatch.delenv(var, raising=False)
    for var in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "ALL_PROXY", "all_proxy"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def asset_yaml(name: str = "toy", layout=None, files=None, registration: bool = False, **extra) -> dict:
    return {
        "schema_version": 1, "name": name, "title": f"{name} asset", "kind": "dataset",
        "source": {"url": "https://example.org/toy", "how_to_get": ["Download toy.tar from the toy page."]},
        "licence": {"name": "CC0-1.0"}, "registration_required": registration, "env_var": "AIRPOSE_TOY_DIR",
        "layout": layout or [{"path": "a.bin"}], "files": files or [], "used_by": ["02_ablation_table"], **extra}


def write_manifest(folder: Path, data: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# -- manifests ------------------------------------------------------------------------------------
def test_every_repo_manifest_loads_and_validates():
    manifests = {m.name: m for m in list_manifests(REPO_MANIFESTS)}
    assert set(OFFICIAL) <= set(manifests)
    assert any(m.generated for m in manifests.values()), "the generator's records are listed too"
    for name in OFFICIAL:
        m = manifests[name]
        assert m.path == REPO_MANIFESTS / f"{name}.yaml" and m.env_var and m.used_by and m.source.how_to_get
        assert any(e.required for e in m.layout)
        if m.registration_required:
            assert not m.files and not m.fetchable
    assert manifests["smplx_v1_1"].env_var == "AIRPOSE_SMPLX_DIR"  # the body loader's variable
    assert manifests["vposer_v02_05"].env_var == "AIRPOSE_VPOSER_DIR"  # the prior loader's variable
    assert manifests["vposer_v02_05"].layout[0].path == "V02_05/snapshots/*.ckpt"
    real = {e.path for e in manifests["official_real"].layout}
    for k in (1, 2):
        assert {f"machine_{k}/images/*.jpg", f"machine_{k}/openpose_res.pkl", f"machine_{k}/alphapose_res.json",
                f"machine_{k}/camera_calib.yml", f"machine_{k}/markerposes_corrected_all.pkl"} <= real
    assert manifests["official_real"].splits["test"]["frames"] == [8000, 14999]
    ckpt = " ".join(e.path for e in manifests["official_checkpoints"].layout)
    for variant in ("hmr", "muhmr", "copenet_singleview", "copenet_twoview"):
        assert f"{variant}_" in ckpt


@pytest.mark.parametrize("name, files", [
    ("official_real", [f"machine_{k}/{f}" for k in (1, 2) for f in (
        "images/000000.jpg", "images/008000.jpg", "openpose_res.pkl", "alphapose_res.json", "camera_calib.yml",
        "markerposes_corrected_all.pkl")]),
    ("official_synthetic", ["dataset/train_pkls.pkl", "dataset/test_pkls.pkl", "dataset/pkls/s1/s1_0.pkl",
                            "data/s1/MyCamera0_0.png"]),
    ("official_checkpoints", ["hmr_synthetic/epoch=1.ckpt", "muhmr_synthetic/ckpt/a.ckpt",
                              "copenet_singleview_ckpt/x/y/b.ckpt", "copenet_twoview_synthetic_ckpt/c.ckpt"]),
    ("smplx_v1_1", ["models/smplx/SMPLX_NEUTRAL.npz", "models/smplx/SMPLX_MALE.npz", "models/smplx/SMPLX_FEMALE.npz"]),
    ("vposer_v02_05", ["V02_05/snapshots/V02_05_epoch=08_val_loss=0.03.ckpt"]),
])
def test_official_layouts_accept_a_minimal_tree(tmp_path, name, files):
    root = tmp_path / name
    for rel in files:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(b"x")
    assert verify(name, root=root).ok, verify(name, root=root).text()
    (root / files[-1]).unlink()  # each listed file is needed
    assert not verify(name, root=root).ok


def test_generated_manifest_becomes_shard_layout(tmp_path):
    record = {"kind": "airpose-still-frames", "profile": "toy", "status": "complete", "seed": 0,
              "shards": [{"file": "shard_00000.npz", "bytes": 3, "sha256": sha(b"abc")}]}
    (tmp_path / "m").mkdir()
    path = tmp_path / "m" / "generated_toy.yaml"
    path.write_text(yaml.safe_dump(record))
    m = read_manifest(path)
    assert m.generated and m.profile == "toy" and not m.fetchable
    shard = [e for e in m.layout if e.path == "shard_00000.npz"][0]
    assert (shard.size, shard.sha256) == (3, sha(b"abc"))
    root = tmp_path / "cache" / "data" / "still_toy"  # where the generator writes it
    root.mkdir(parents=True)
    # the dataset's own manifest (with this machine's bytes) is what the shards are checked against
    (root / "manifest.yaml").write_text(yaml.safe_dump(record))
    (root / "shard_00000.npz").write_bytes(b"abc")
    assert verify("generated_toy", manifests=tmp_path / "m").ok
    (root / "shard_00000.npz").write_bytes(b"abd")
    report = verify("generated_toy", manifests=tmp_path / "m")
    assert [r.status for r in report.results if r.entry.path == "shard_00000.npz"] == [CHECKSUM_MISMATCH]
    assert "airpose data generate --profile toy" in report.text()
    with pytest.raises(FetchError, match="airpose data generate --profile toy"):
        fetch("generated_toy", manifests=tmp_path / "m")


@pytest.mark.parametrize("change, field", [
    ({"licence": None}, "licence"),
    ({"colour": "red"}, "unknown key"),
    ({"kind": "movie"}, "kind"),
    ({"name": "other"}, "name"),
    ({"layout": [{"path": "../etc/passwd"}]}, "layout[0].path"),
    ({"layout": [{"path": "a.bin", "sha256": "abc"}]}, "layout[0].sha256"),
    ({"layout": [{"path": "*.bin", "size": 3}]}, "layout[0]"),
    ({"used_by": ["ablation"]}, "used_by[0]"),
    ({"registration_required": True, "files": [{"name": "a.bin", "url": "https://x.org/a"}]}, "files"),
    ({"files": [{"name": "a.bin", "url": "ftp://x.org/a"}]}, "files[0].url"),
])
def test_schema_errors_name_the_file_and_field(tmp_path, change, field):
    data = asset_yaml()
    data.update(change)
    if data.get("licence") is None:
        del data["licence"]
    path = write_manifest(tmp_path / "m", data) if data["name"] == "toy" else None
    if path is None:  # name mismatch: the file is still toy.yaml
        path = tmp_path / "m" / "toy.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(yaml.safe_dump(data))
    with pytest.raises(ManifestError) as err:
        read_manifest(path)
    assert str(path) in str(err.value) and field in str(err.value)


def test_unknown_asset_lists_the_known_ones(tmp_path):
    write_manifest(tmp_path / "m", asset_yaml())
    with pytest.raises(AssetError, match="known: toy"):
        load_asset_manifest("nope", tmp_path / "m")
    with pytest.raises(AssetError, match="does not exist"):
        manifest_dir(tmp_path / "absent")


# -- locate ---------------------------------------------------------------------------------------
def test_locate_order_argument_env_config_default(tmp_path, monkeypatch):
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml())
    assert locate("toy", manifests=mdir).path == tmp_path / "cache" / "assets" / "toy"
    assert locate("toy", manifests=mdir).origin == "default"

    xdg = tmp_path / "xdg" / "airpose" / "assets.yaml"  # ~/.config/airpose/assets.yaml via XDG_CONFIG_HOME
    xdg.parent.mkdir(parents=True)
    xdg.write_text("toy: from_xdg\n")
    loc = locate("toy", manifests=mdir)
    assert (loc.origin, loc.path) == ("config", xdg.parent / "from_xdg")  # relative to the config file

    explicit = tmp_path / "conf" / "assets.yaml"
    explicit.parent.mkdir()
    explicit.write_text(f"toy: {tmp_path / 'from_config'}\nother: /x\n")
    monkeypatch.setenv("AIRPOSE_ASSETS_CONFIG", str(explicit))
    assert locate("toy", manifests=mdir).path == tmp_path / "from_config"

    monkeypatch.setenv("AIRPOSE_TOY_DIR", str(tmp_path / "from_env"))
    loc = locate("toy", manifests=mdir)
    assert (loc.origin, loc.path, loc.detail) == ("env", tmp_path / "from_env", "$AIRPOSE_TOY_DIR")

    assert locate("toy", root=tmp_path / "arg", manifests=mdir).path == tmp_path / "arg"


def test_locate_bad_config_is_a_clear_error(tmp_path, monkeypatch):
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml())
    monkeypatch.setenv("AIRPOSE_ASSETS_CONFIG", str(tmp_path / "missing.yaml"))
    with pytest.raises(AssetError, match="missing.yaml.*does not exist"):
        locate("toy", manifests=mdir)
    bad = tmp_path / "bad.yaml"
    bad.write_text("- a\n- b\n")
    monkeypatch.setenv("AIRPOSE_ASSETS_CONFIG", str(bad))
    with pytest.raises(AssetError, match="bad.yaml must be a YAML mapping"):
        locate("toy", manifests=mdir)


def test_repo_assets_default_and_env(tmp_path, monkeypatch):
    assert locate("smplx_v1_1").path == tmp_path / "cache" / "assets" / "smplx_v1_1"
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path / "smplx"))
    assert locate("smplx_v1_1").path == tmp_path / "smplx"


# -- verify ---------------------------------------------------------------------------------------
A, B, C = b"alpha" * 10, b"bravo" * 10, b"charlie" * 10


def toy_layout():
    return [
        {"path": "a.bin", "size": len(A), "sha256": sha(A)},
        {"path": "b.bin", "size": len(B), "sha256": sha(B)},
        {"path": "c.bin", "size": len(C), "sha256": sha(C)},
        {"path": "frames/*.jpg", "min_count": 2},
        {"path": "extra/notes.txt", "required": False},
        {"path": "model.npz", "alternatives": ["models/model.npz"]},
    ]


def test_verify_reports_each_problem_and_the_fix(tmp_path):
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml(layout=toy_layout()))
    root = tmp_path / "toy"
    (root / "frames").mkdir(parents=True)
    (root / "a.bin").write_bytes(A)
    (root / "b.bin").write_bytes(B[:-1])  # truncated
    (root / "c.bin").write_bytes(C[:-1] + b"X")  # same size, altered
    (root / "frames" / "000000.jpg").write_bytes(b"j")  # one of at least two
    (root / "models").mkdir()
    (root / "models" / "model.npz").write_bytes(b"m")  # found at its alternative place

    report = verify("toy", root=root, manifests=mdir)
    status = {r.entry.path: r.status for r in report.results}
    assert status == {"a.bin": PRESENT, "b.bin": SIZE_MISMATCH, "c.bin": CHECKSUM_MISMATCH,
                      "frames/*.jpg": MISSING, "extra/notes.txt": MISSING, "model.npz": PRESENT}
    assert not report.ok
    assert {r.entry.path for r in report.problems} == {"b.bin", "c.bin", "frames/*.jpg"}  # optional is fine
    text = report.text()
    assert "49 bytes, the manifest says 50" in text and "found 1, need at least 2 files" in text
    assert str(root / "c.bin") in text and "Download toy.tar from the toy page." in text
    assert "AIRPOSE_TOY_DIR" in text and "never overwrites" in text

    # without checksums the altered file of the right size passes; the truncated one still fails
    quick = {r.entry.path: r.status for r in verify("toy", root=root, checksums=False, manifests=mdir).results}
    assert quick["c.bin"] == PRESENT and quick["b.bin"] == SIZE_MISMATCH

    (root / "b.bin").write_bytes(B)
    (root / "c.bin").write_bytes(C)
    (root / "frames" / "000001.jpg").write_bytes(b"j")
    report = verify("toy", root=root, manifests=mdir)
    assert report.ok and "OK" in report.text()


def test_verify_missing_folder_and_nested_layout(tmp_path, monkeypatch):
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml(layout=[{"path": "a.bin"}]))
    report = verify("toy", manifests=mdir)
    assert not report.ok and "does not exist" in report.text() and "Missing: all of it" in report.text()
    nested = tmp_path / "toy" / "unpacked_top"
    nested.mkdir(parents=True)
    (nested / "a.bin").write_bytes(b"a")
    monkeypatch.setenv("AIRPOSE_TOY_DIR", str(tmp_path / "toy"))
    report = verify("toy", manifests=mdir)
    assert not report.ok and f"seems to be in {nested}" in report.text()


# -- fetch ----------------------------------------------------------------------------------------
class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):  # keep the test output clean
        pass


@pytest.fixture
def server(tmp_path):
    """(folder, base URL) of an HTTP server on 127.0.0.1 serving the folder."""
    folder = tmp_path / "served"
    folder.mkdir()
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler, directory=str(folder)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield folder, f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()
    thread.join(5)


def make_tar(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    return buf.getvalue()


@pytest.fixture
def fetchable(tmp_path, server):
    """A manifest with a plain file and a tar archive (one top folder) on the loopback server."""
    folder, url = server
    archive = make_tar({"pack/inner/x.txt": b"from archive x", "pack/y.txt": b"from archive y"})
    (folder / "data.bin").write_bytes(A)
    (folder / "pack.tar.gz").write_bytes(archive)
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml(
        layout=[{"path": "data.bin", "size": len(A), "sha256": sha(A)}, {"path": "inner/x.txt"}, {"path": "y.txt"}],
        files=[{"name": "data.bin", "url": "https://unreachable.invalid/data.bin", "sha256": sha(A), "size": len(A)},
               {"name": "pack.tar.gz", "url": "https://unreachable.invalid/pack.tar.gz", "sha256": sha(archive),
                "extract": "tar", "extract_to": "."}]))
    return mdir, folder, url


def test_fetch_downloads_checks_and_unpacks(tmp_path, fetchable):
    mdir, _folder, url = fetchable
    root = tmp_path / "toy"
    report = fetch("toy", root=root, base_url=url, manifests=mdir)
    assert report.ok, report.text()
    assert [o.status for o in report.outcomes] == ["downloaded", "downloaded"]
    assert (root / "data.bin").read_bytes() == A
    assert (root / "inner" / "x.txt").read_bytes() == b"from archive x"  # top folder pack/ dropped
    assert (root / "y.txt").read_bytes() == b"from archive y"
    assert not [p for p in root.iterdir() if ".fetch-" in p.name or ".unpack-" in p.name]  # no staging left
    assert verify("toy", root=root, manifests=mdir).ok

    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}
    again = fetch("toy", root=root, base_url=url, manifests=mdir)
    assert [o.status for o in again.outcomes] == ["already-present", "already-present"]
    assert "already unpacked" in again.outcomes[1].extraction
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()} == before


def test_fetch_tampered_file_is_rejected_and_leaves_nothing(tmp_path, fetchable):
    mdir, folder, url = fetchable
    (folder / "data.bin").write_bytes(A[:-1] + b"!")  # the server's copy changed after the manifest
    root = tmp_path / "toy"
    with pytest.raises(ChecksumError, match="does not match the manifest's SHA-256"):
        fetch("toy", root=root, base_url=url, manifests=mdir)
    assert list(root.iterdir()) == []  # no partial file, no staging folder


def test_fetch_never_modifies_the_users_files(tmp_path, fetchable):
    mdir, _folder, url = fetchable
    root = tmp_path / "toy"
    (root / "inner").mkdir(parents=True)
    (root / "data.bin").write_bytes(b"my own data")
    (root / "inner" / "x.txt").write_bytes(b"my edit")
    stamps = {p: p.stat().st_mtime_ns for p in (root / "data.bin", root / "inner" / "x.txt")}
    report = fetch("toy", root=root, base_url=url, manifests=mdir)
    assert not report.ok
    conflict = report.outcomes[0]
    assert conflict.status == "conflict" and "left untouched" in conflict.detail
    assert (root / "data.bin").read_bytes() == b"my own data"
    assert (root / "inner" / "x.txt").read_bytes() == b"my edit"  # the archive's copy did not replace it
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    assert "kept 1 existing files unchanged" in report.outcomes[1].extraction
    assert (root / "y.txt").read_bytes() == b"from archive y"  # what was not there is added
    assert "conflict" in report.text()


def test_fetch_unverified_needs_consent_and_reports_the_hash(tmp_path, server):
    folder, url = server
    (folder / "raw.bin").write_bytes(B)
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml(layout=[{"path": "raw.bin"}],
                                    files=[{"name": "raw.bin", "url": f"{url}/raw.bin", "sha256": None}]))
    root = tmp_path / "toy"
    with pytest.raises(FetchError, match="--allow-unverified"):
        fetch("toy", root=root, manifests=mdir)
    assert not (root / "raw.bin").exists()
    report = fetch("toy", root=root, manifests=mdir, allow_unverified=True)
    assert report.ok and report.outcomes[0].sha256 == sha(B)
    assert sha(B) in report.text()
    assert (root / "raw.bin").read_bytes() == B


def test_fetch_network_error_is_a_fetch_error(tmp_path, fetchable):
    mdir, folder, url = fetchable
    (folder / "data.bin").unlink()  # 404
    root = tmp_path / "toy"
    with pytest.raises(FetchError, match="download of .*data.bin failed"):
        fetch("toy", root=root, base_url=url, manifests=mdir)
    assert list(root.iterdir()) == []


@pytest.mark.parametrize("name", ["smplx_v1_1", "vposer_v02_05"])
def test_registration_assets_refuse_to_fetch(tmp_path, name):
    root = tmp_path / name
    with pytest.raises(RegistrationRequired) as err:
        fetch(name, root=root, base_url="http://127.0.0.1:9")
    text = str(err.value)
    assert "register" in text and "https://smpl-x.is.tue.mpg.de" in text and "redistribution" in text
    assert load_asset_manifest(name).env_var in text
    assert not root.exists()


# -- data source ----------------------------------------------------------------------------------
def test_resolve_data_source_falls_back_with_a_message(tmp_path, monkeypatch):
    mdir = tmp_path / "m"
    write_manifest(mdir, asset_yaml(layout=[{"path": "a.bin"}]))
    src = resolve_data_source("official", ["toy"], manifests=mdir)
    assert src.source == "generated" and src.fell_back and not src.roots
    assert "toy" in src.message and "falling back" in src.message
    assert "Download toy.tar from the toy page." in src.message and "AIRPOSE_TOY_DIR" in src.message

    root = tmp_path / "toy"
    root.mkdir()
    (root / "a.bin").write_bytes(b"a")
    monkeypatch.setenv("AIRPOSE_TOY_DIR", str(root))
    src = resolve_data_source("official", ["toy"], manifests=mdir)
    assert src.source == "official" and not src.fell_back and src.roots == {"toy": root}

    gen = resolve_data_source("generated", ["toy"], manifests=mdir)
    assert gen.source == "generated" and not gen.fell_back and "generated" in gen.message
    with pytest.raises(ValueError, match="data source must be one of"):
        resolve_data_source("real", ["toy"], manifests=mdir)


def test_resolve_official_real_without_data_falls_back():
    src = resolve_data_source("official", ["official_real", "smplx_v1_1"])
    assert src.source == "generated" and "official_real, smplx_v1_1" in src.message
    assert "keeper.mpdl.mpg.de" in src.message and "smpl-x.is.tue.mpg.de" in src.message


# -- command line ---------------------------------------------------------------------------------
def run_cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="airpose data")
    add_asset_commands(parser.add_subparsers(dest="data_command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli_verify_exit_status_and_fetch_refusal(tmp_path, capsys):
    from airpose_lib.errors import UserError  # RegistrationRequired: the `airpose` command's one line

    path = write_manifest(tmp_path / "m", asset_yaml(layout=[{"path": "a.bin"}]))
    root = tmp_path / "toy"
    root.mkdir()
    assert run_cli(["verify", str(path), "--root", str(root)]) == 1
    assert "Missing: a.bin" in capsys.readouterr().out
    (root / "a.bin").write_bytes(b"a")
    assert run_cli(["verify", str(path), "--root", str(root)]) == 0
    with pytest.raises(UserError, match="register"):
        run_cli(["fetch", "smplx_v1_1", "--root", str(tmp_path / "s")])
    assert run_cli(["list", "--no-check"]) == 0
    out = capsys.readouterr().out
    assert "official_real" in out and "register" in out
