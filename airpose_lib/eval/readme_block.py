"""The generated result blocks: a committed reference bundle (``results/<profile>/``) as the short
Markdown of the README and the docs pages, so that no number there is typed by hand.

The block sits between two HTML comments, ``<!-- results:<profile> -->`` and
``<!-- /results:<profile> -->``; ``scripts/readme_results.py`` rewrites it from the bundle and
``tests/test_readme_block.py`` fails when a page's block and the bundle disagree. A second
kind of block, ``<!-- recordings:<profile> -->``, holds the recordings' UAV2-in-UAV1 table
against the ArUco markers (:func:`recordings_block`, from ``results/<profile>/recordings/``).
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd

from airpose_lib.paths import RunFolders

from .reference import reference_dir

__all__ = ["block_markers", "results_block", "recordings_block", "video_block", "replace_block", "readme_block"]

#: Table I's columns shown in the README: the kit's mean (± its seed spread) next to the paper's.
_TABLE_COLUMNS = (("MPE", "MPE [m]", "MPE std [m]", "MPE paper [m]"),
                  ("MPJPE", "MPJPE [m]", "MPJPE std [m]", "MPJPE paper [m]"))


def block_markers(name: str, kind: str = "results") -> tuple[str, str]:
    """The opening and closing comment of the profile ``name``'s block of ``kind`` (``results``: Table I;
    ``recordings``: :func:`recordings_block`)."""
    return f"<!-- {kind}:{name} -->", f"<!-- /{kind}:{name} -->"


def _block_pattern(name: str, kind: str = "results") -> re.Pattern:
    """The block of the profile ``name``, markers included, in a text."""
    opening, closing = block_markers(name, kind)
    return re.compile(re.escape(opening) + r".*?" + re.escape(closing), re.S)


def _fmt(x, digits: int = 3) -> str:
    return "-" if pd.isna(x) else f"{x:.{digits}f}"


def _table_lines(table: pd.DataFrame) -> list[str]:
    root = "root orient. median [deg]"
    head = ["method"] + [f"{name} {who} [m]" for name, *_ in _TABLE_COLUMNS for who in ("kit", "paper")] + \
        (["root median [deg]"] if root in table else [])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method, row in table.iterrows():
        cells = [str(method)]
        for _, mean, std, paper in _TABLE_COLUMNS:
            spread = row.get(std)
            cells += [_fmt(row.get(mean)) + ("" if pd.isna(spread) else f" ± {spread:.3f}"), _fmt(row.get(paper))]
        cells += [_fmt(row.get(root), 1)] if root in table else []
        lines.append("| " + " | ".join(cells) + " |")
    return lines


#: A gain counts as reaching the paper's when it is at least this share of the paper's gain.
TARGET_SHARE = 1 / 3


def _missed(c: pd.Series) -> bool:
    """Whether a claim's gain falls short of :data:`TARGET_SHARE` of the paper's."""
    return float(c["gain [%]"]) < float(c["paper gain [%]"]) * TARGET_SHARE


def _target_cell(c: pd.Series) -> str:
    """A third of the paper's gain and whether the kit's gain reaches it."""
    return f"{float(c['paper gain [%]']) * TARGET_SHARE:.1f} ({'missed' if _missed(c) else 'met'})"


def _claim_lines(claims: pd.DataFrame) -> list[str]:
    has_gain = "gain [%]" in claims
    head = ["claim", "difference [m] (95 % CI)"] + \
        (["gain [%] (95 % CI)", "paper gain [%]", "a third of the paper's [%]"] if has_gain else []) + ["verdict"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, c in claims.iterrows():
        cells = [str(c["claim"]), f"{c['difference [m]']:+.4f} ({c['CI low [m]']:+.4f}, {c['CI high [m]']:+.4f})"]
        if has_gain:
            cells += [f"{c['gain [%]']:+.1f} ({c['gain CI low [%]']:+.1f}, {c['gain CI high [%]']:+.1f})",
                      _fmt(c["paper gain [%]"], 1), _target_cell(c)]
        lines.append("| " + " | ".join(cells + [str(c["verdict"])]) + " |")
    return lines


def _mechanism_value(m: pd.DataFrame, part: str, input_has: str, readout: str, metric: str) -> pd.Series | None:
    """One row of ``mechanism.csv`` (None when it has no such row)."""
    row = m[(m["part"] == part) & m["input"].str.contains(input_has, regex=False) & (m["readout"] == readout)
            & (m["metric"] == metric)]
    return None if row.empty else row.iloc[0]


def _bound_lines(ref: Path, name: str, claims: pd.DataFrame) -> list[str]:
    """Beside each missed ordering, what this data allows (``results/<profile>/mechanism/``, when
    made): for MPE, the cut in the first method's MPE that one depth scale shared by the two views
    would give, and how much stature the views' features carry; for MPJPE, the gain with the
    body pose alone (both methods with the true root orientation) and with an exact root
    orientation for the second method (part ``d``)."""
    path = ref / "mechanism" / "mechanism.csv"
    if not path.is_file() or "gain [%]" not in claims:
        return []
    m = pd.read_csv(path)
    lines = ["", f"Where a gain misses a third of the paper's, what this data allows "
                 f"(`results/{name}/mechanism/`, validation split, 95 % intervals over two-view samples):", ""]
    missed = [c for _, c in claims.iterrows() if _missed(c)]
    for c in missed:
        metric, pair = str(c["claim"]).split(": ", 1)
        first = pair.split(" > ")[0]
        row = _mechanism_value(m, "c", "shared scalar", first, "gain over measured [%]")
        if metric == "MPE" and row is not None:
            lines.append(f"- {c['claim']}: one depth scale shared by the two views, the most an exchanged body "
                         f"number could give, would cut {first}'s MPE by at most {row['value']:.1f} % "
                         f"({row['CI low']:.1f}, {row['CI high']:.1f}); the exchange buys {float(c['gain [%]']):.1f} % "
                         f"against the paper's {float(c['paper gain [%]']):.1f} %.")
            continue
        alone = _mechanism_value(m, "d", "body pose alone", pair, "gain [%]")
        exact = _mechanism_value(m, "d", "exact root", pair, "gain [%]")
        if metric == "MPJPE" and alone is not None and exact is not None:
            second = pair.split(" > ")[1]
            lines.append(f"- {c['claim']}: scored with the true root orientation (the body pose alone) the gain is "
                         f"{alone['value']:+.1f} % ({alone['CI low']:+.1f}, {alone['CI high']:+.1f}); with an exact "
                         f"root orientation {second} would gain {exact['value']:+.1f} % ({exact['CI low']:+.1f}, "
                         f"{exact['CI high']:+.1f}); the ordering buys {float(c['gain [%]']):.1f} % against the "
                         f"paper's {float(c['paper gain [%]']):.1f} %.")
        else:
            lines.append(f"- {c['claim']}: no bound measured; the measured reason is in docs/findings.md.")
    one = _mechanism_value(m, "a", "features + P", "ridge", "R2")
    both = _mechanism_value(m, "a", "features + P", "ridge", "R2 of the views' mean")
    shared = _mechanism_value(m, "a", "features + P", "ridge", "view error correlation")
    if missed and one is not None and both is not None and shared is not None and "stature" in str(one["quantity"]):
        lines.append(f"- What the views could exchange about the body: stature read from one view's features and "
                     f"P, R² {one['value']:.2f} ({one['CI low']:.2f}, {one['CI high']:.2f}); from the two views' "
                     f"mean reading, R² {both['value']:.2f}; the two views' stature errors correlate "
                     f"{shared['value']:.2f}, so an exchange has little to average.")
    return lines if missed else []


def results_block(name: str, root: str | Path | None = None) -> str:
    """The block's Markdown (markers included) made from ``results/<profile>/``: Table I (kit mean
    ± seed spread, the paper's), the claims with their intervals and gains, the measured bound of
    what an exchange could buy (when ``mechanism/`` is there), and the provenance (commit, date,
    command).

    Raises:
        FileNotFoundError: the bundle lacks ``table1.csv``, ``claims.csv`` or ``provenance.json``.
    """
    ref = reference_dir(RunFolders(name), root)
    table = pd.read_csv(ref / "table1.csv", index_col=0)
    claims = pd.read_csv(ref / "claims.csv")
    prov = json.loads((ref / "provenance.json").read_text())
    commit = (prov.get("git") or {}).get("commit") or "unknown"
    seeds = prov.get("seeds") or []
    opening, closing = block_markers(name)
    lines = [opening,
             f"Table I on the `{name}` profile (`results/{name}/`: {len(seeds)} seed{'s' * (len(seeds) != 1)}, "
             f"commit {commit[:7]}, {str(prov.get('created_at', ''))[:10]}; `{prov.get('command', '')}`). "
             "Kit: mean ± standard deviation over seeds; paper: its Table I.", "",
             *_table_lines(table), "",
             "The paper's orderings (\"A > B\": A's error is larger), paired over the test samples:", "",
             *_claim_lines(claims), *_bound_lines(ref, name, claims), closing]
    return "\n".join(lines)


#: The recordings' marker tables (notebook 05) and how the README names each.
_MARKER_TABLES = (("markers.csv", "clean"), ("field_markers.csv", "field"))


def recordings_block(name: str, root: str | Path | None = None) -> str | None:
    """The README's block (markers included) of the recordings' UAV2 in UAV1 against the ArUco
    markers, from ``results/<profile>/recordings/`` (``markers.csv``, ``field_markers.csv``):
    per recording and person, the markers against the generated cameras, then each method against
    both references, medians. None when the bundle has no marker table."""
    ref = reference_dir(RunFolders(name), root) / "recordings"
    parts = [pd.read_csv(ref / name).assign(recordings=tag) for name, tag in _MARKER_TABLES if (ref / name).is_file()]
    if not parts:
        return None
    prov = json.loads((ref / "provenance.json").read_text())
    commit = (prov.get("git") or {}).get("commit") or "unknown"
    head = ["recordings", "person", "method", "reference", "frames", "position median [m]",
            "orientation median [deg]"]
    lines = [*block_markers(name, "recordings")[:1],
             f"UAV2 in UAV1 on the `{name}` recordings (`results/{name}/recordings/`: commit {commit[:7]}, "
             f"{str(prov.get('created_at', ''))[:10]}; `{prov.get('command', '')}`): the ArUco markers against the "
             "cameras the renderer used, then each method against both; medians over the frames where the markers "
             "posed both drones and every network estimated both views.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in pd.concat(parts, ignore_index=True).iterrows():
        lines.append("| " + " | ".join([r["recordings"], str(r["sequence"]), str(r["method"]), str(r["reference"]),
                                        str(int(r["frames"])), _fmt(r["rel_t_median_m"]),
                                        _fmt(r["rel_rot_median_deg"], 2)]) + " |")
    return "\n".join(lines + [block_markers(name, "recordings")[1]])


def video_block(name: str, root: str | Path | None = None) -> str | None:
    """The video route on known truth (``results/<name>/video/``, written by
    :func:`airpose_lib.experiments.video_check.write_video_reference`): per recording and method,
    the median errors of ``airpose video`` next to the same networks on the recording's frames,
    the offset found, and the seconds per 100 frames; None without that folder."""
    ref = reference_dir(RunFolders(name), root) / "video"
    if not (ref / "known_truth.csv").is_file():
        return None
    t = pd.read_csv(ref / "known_truth.csv")
    prov = json.loads((ref / "provenance.json").read_text())
    commit = (prov.get("git") or {}).get("commit") or "unknown"
    opening, closing = block_markers(name, "video")
    lines = [opening, f"`airpose video` on known truth (`results/{name}/video/`: commit {commit[:7]}, "
             f"{prov.get('created_at', '')[:10]}; `{prov.get('command', '')}`): UAV2's video started "
             f"{prov.get('shift')} frames late; medians over the paired frames, the video route against the same "
             "networks on the recording's own frames.", "",
             "| recordings | method | frames | MPJPE video / recording [m] | UAV2 in UAV1 position video / recording [m] "
             "| orientation video / recording [deg] | offset found (true) | s per 100 frames |",
             "|---|---|---|---|---|---|---|---|"]
    for (recs, method), g in t.groupby(["recordings", "method"], sort=False):
        v, r = g[g["route"] == "video"].iloc[0], g[g["route"] == "recording"].iloc[0]
        timing = prov.get("timing", {}).get(recs, {})
        found = f"{int(v['offset_frames']):+d}" if recs == next(iter(prov["recordings"])) else "given"
        lines.append(f"| {recs} | {method} | {int(v['frames'])} | {_fmt(v['mpjpe_median_m'], 4)} / "
                     f"{_fmt(r['mpjpe_median_m'], 4)} | {_fmt(v['uav2_in_uav1_position_median_m'])} / "
                     f"{_fmt(r['uav2_in_uav1_position_median_m'])} | {_fmt(v['uav2_in_uav1_orientation_median_deg'], 2)}"
                     f" / {_fmt(r['uav2_in_uav1_orientation_median_deg'], 2)} | {found} ({int(r['offset_frames']):+d}) | "
                     f"{_fmt(timing.get('seconds_per_100_frames'), 0)} |")
    lines.append(closing)
    return "\n".join(lines)


def replace_block(text: str, block: str, name: str, kind: str = "results") -> str:
    """``text`` with the profile ``name``'s block of ``kind`` replaced by ``block``.

    Raises:
        ValueError: ``text`` lacks the block's markers.
    """
    pattern = _block_pattern(name, kind)
    if not pattern.search(text):
        raise ValueError(f"no {' ... '.join(block_markers(name, kind))} block")
    return pattern.sub(lambda _: block, text, count=1)


def readme_block(text: str, name: str, kind: str = "results") -> str | None:
    """The block of the profile ``name`` of ``kind`` in ``text`` (markers included), or None."""
    m = _block_pattern(name, kind).search(text)
    return m.group(0) if m else None
