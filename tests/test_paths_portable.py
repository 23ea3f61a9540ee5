"""``paths.portable``: a committed record names no folder of the machine that made it; every
expected value below is written out by hand."""
from __future__ import annotations

from pathlib import Path, PurePosixPath

from airpose_lib import paths
from airpose_lib.paths import portable

# a checkout whose runs folder lies inside it, a cache inside the home folder
ROOTS = {"<checkout>": "/home/ana/airpose", "<runs>": "/home/ana/airpose/runs",
         "<cache>": "/home/ana/.cache/airpose", "~": "/home/ana"}


def test_each_root_is_named_by_its_placeholder():
    assert portable("/home/ana/airpose/profiles/cpu.yaml", ROOTS) == "<checkout>/profiles/cpu.yaml"
    assert portable("/home/ana/airpose/runs/train/cpu/airpose/seed123", ROOTS) == "<runs>/train/cpu/airpose/seed123"
    assert portable("/home/ana/.cache/airpose/prior/cpu/vposer.pt", ROOTS) == "<cache>/prior/cpu/vposer.pt"
    assert portable("/home/ana/data/clip.mp4", ROOTS) == "~/data/clip.mp4"
    assert portable("/home/ana/.cache/airpose", ROOTS) == "<cache>"  # the root itself


def test_the_deepest_root_wins_whatever_the_order_given():
    reversed_roots = dict(reversed(list(ROOTS.items())))
    assert portable("/home/ana/airpose/runs/x/y", reversed_roots) == "<runs>/x/y"
    assert portable("/home/ana/.cache/airpose/x", reversed_roots) == "<cache>/x"


def test_a_root_is_a_folder_not_a_prefix_of_a_name():
    assert portable("/home/ana/airpose-old/x/y.pt", ROOTS) == "~/airpose-old/x/y.pt"
    assert portable("/home/anabel/x/y.pt", ROOTS) == "<abs>/x/y.pt"


def test_other_absolute_paths_keep_their_last_two_names():
    assert portable("/tmp/runs/straight/eval_val", ROOTS) == "<abs>/straight/eval_val"
    assert portable("/work/sel/fourth/cpu_fourth_mirror.yaml", ROOTS) == "<abs>/fourth/cpu_fourth_mirror.yaml"
    assert portable("/tmp/x/y/", ROOTS) == "<abs>/x/y/"
    assert portable("/opt/x", ROOTS) == "<abs>/opt/x"
    assert portable("/tmp", ROOTS) == "/tmp"  # one name: nothing to hide, nothing to keep


def test_paths_inside_text():
    cmd = "airpose pretrain --profile /work/sel/third/cpu_third.yaml --out /home/ana/airpose/runs/p"
    assert portable(cmd, ROOTS) == "airpose pretrain --profile <abs>/third/cpu_third.yaml --out <runs>/p"
    assert portable("written to /tmp/runs/straight/eval_val.", ROOTS) == "written to <abs>/straight/eval_val."
    assert portable("prior (/home/ana/.cache/airpose/prior/cpu/x.pt)", ROOTS) == "prior (<cache>/prior/cpu/x.pt)"
    assert portable("a='/tmp/a/b', b=\"/tmp/c/d\"", ROOTS) == "a='<abs>/a/b', b=\"<abs>/c/d\""


def test_html_text_is_rewritten_and_its_markup_left_alone():
    cell = '<span class="n">output_dir</span> = <span class="s2">&quot;/work/runs6/cpu/02_ablation_table&quot;</span>'
    assert portable(cell, ROOTS) == ('<span class="n">output_dir</span> = '
                                     '<span class="s2">&quot;<abs>/cpu/02_ablation_table&quot;</span>')
    assert portable("<td>/home/ana/.cache/airpose/data/still_cpu</td>", ROOTS) == "<td><cache>/data/still_cpu</td>"
    untouched = ('<script src="https://cdnjs.cloudflare.com/ajax/libs/require.js/2.1.10/require.min.js"></script>'
                 '<br/> 1/2 and/or m /s <img src="data:image/jpeg;base64,/9j/4AAQ/2wBD+/x=="> '
                 '# None: &lt;kit cache&gt;/data/still_&lt;profile&gt;')
    assert portable(untouched, ROOTS) == untouched


def test_nesting_keys_and_types():
    record = {"command": "airpose pretrain --profile /tmp/p/q.yaml", "steps": 40, "gate": None,
              "config": {"data": {"root": "/home/ana/.cache/airpose/data/still_cpu"}, "lr": 1e-3,
                         "pretrained": PurePosixPath("/home/ana/.cache/airpose/backbones/k.pt")},
              "files": ["/home/ana/airpose/runs/a/b", ("/tmp/x/y", 3)],
              "/home/ana/airpose/results/cpu": True}
    assert portable(record, ROOTS) == {
        "command": "airpose pretrain --profile <abs>/p/q.yaml", "steps": 40, "gate": None,
        "config": {"data": {"root": "<cache>/data/still_cpu"}, "lr": 1e-3, "pretrained": "<cache>/backbones/k.pt"},
        "files": ["<runs>/a/b", ("<abs>/x/y", 3)],
        "<checkout>/results/cpu": True}


def test_a_second_call_changes_nothing_and_relative_paths_stay():
    once = portable("/tmp/a/b /home/ana/x/y /home/ana/airpose/runs/c ~/d/e runs/f results/cpu/x.json", ROOTS)
    assert once == "<abs>/a/b ~/x/y <runs>/c ~/d/e runs/f results/cpu/x.json"
    assert portable(once, ROOTS) == once


def test_default_roots_are_this_machines(monkeypatch, tmp_path):
    monkeypatch.setenv(paths.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.setenv(paths.RUNS_ENV, str(tmp_path / "runs"))
    checkout = Path(__file__).resolve().parents[1]
    assert portable(str(tmp_path / "cache" / "prior" / "vposer.pt")) == "<cache>/prior/vposer.pt"
    assert portable(str(tmp_path / "runs" / "cpu")) == "<runs>/cpu"
    assert portable(str(checkout / "profiles" / "cpu.yaml")) == "<checkout>/profiles/cpu.yaml"
    assert portable(str(Path.home() / "elsewhere" / "x" / "y")) in ("~/elsewhere/x/y", "<abs>/x/y")
