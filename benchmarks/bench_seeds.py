"""Two settings fitted with several seeds: what a change does beyond the sampler's noise, car by car.

The fine stage samples, and the seed alone moves a variant's count of cars within 1 m or
passing KITTI's 3D IoU 0.7 by several cars on a fold group (the shipped part model's `full`
passes IoU 0.7 for 64 to 79 of the 294 cars over seven seeds; `benchmarks/RESULTS.md`, "the
same label boxes with another seed"). So a change is judged over several seeds, and its counts are read
from the records rather than converted from percentages by hand. This reads runs of
``bench_real_folds.py`` for two settings A and B, paired by seed (the k-th run of A with the
k-th of B, same frames and boxes; the seeds the runs' summaries record must agree), and
reports, per variant and fold group ({0, 1}, {2, 3}, all):

* per seed and summed, A -> B: the true positives, the cars within 1 m, the cars passing
  3D IoU > 0.7 and the mean 3D IoU of the true positives (a measure with no threshold);
* at how many seeds B is ahead, level and behind on each;
* the sampler's share: of the cars that are true positives in every run of a setting, how
  many pass at every seed, at some seeds only, at none;
* car by car, over the cars that are true positives in every run of both: how many B
  passes at more seeds than A and how many at fewer, with a two-sided sign test of the
  two counts;
* the same car-by-car counts, and the passes summed over the seeds, by distance band,
  KITTI occlusion flag and truncation (:func:`bench_error_budget.group_masks` of the
  first run of A): where a change gains and where it loses.

    python benchmarks/bench_seeds.py --root KITTI A=RUN_A1,RUN_A2[,...] B=RUN_B1,RUN_B2[,...] \\
        [--variant full --variant fg+gp] [--json OUT]

True positives and passes are counted as :mod:`bench_error_budget` counts them (the
evaluation's own matching; label boxes make every car a true positive).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bench_error_budget import KITTI_CAMERA_HEIGHT, group_masks, run_tables  # noqa: E402  (benchmarks/ is on the path)
from wirescene.core.jsonio import write_json
from wirescene.io.folds import DRIVE_FOLDS, FOLD_GROUPS, frame_drives
from wirescene.io.kitti import KittiDataset

#: The fold groups of every choice (chosen on the first, read on the second), and all folds.
GROUPS: dict[str, tuple[int, ...]] = {"{" + ", ".join(map(str, g)) + "}": g for g in FOLD_GROUPS}
GROUPS["all"] = tuple(f for g in FOLD_GROUPS for f in g)
#: The tests counted per car: the paper's (centre within 1 m) and KITTI's (3D IoU > 0.7).
TESTS: dict[str, str] = {"within 1 m": "pass_loc", "IoU > 0.7": "pass_iou"}


def run_seed(run: Path) -> int | None:
    """The seed ``bench_real_folds.py`` recorded in ``RUN/summary.json`` (None if it recorded none)."""
    path = Path(run) / "summary.json"
    if not path.is_file():
        return None
    seed = json.loads(path.read_text()).get("_run", {}).get("seed")
    return None if seed is None else int(seed)


def seed_run_parser(doc: str) -> argparse.ArgumentParser:
    """The command line of a benchmark reading several seeds' runs of one setting:
    ``RUN,RUN[,...] --root KITTI [--variant V ...] [--json OUT]`` (``doc`` its description)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", metavar="RUN,RUN[,...]", help="bench_real_folds.py --out directories of one setting")
    ap.add_argument("--root", required=True, help="the KITTI root the runs were fitted on")
    ap.add_argument("--variant", action="append", help="variants (default: those every run holds)")
    ap.add_argument("--json", type=Path)
    return ap


def seed_runs(ap: argparse.ArgumentParser, text: str) -> tuple[list[Path], list[int | None]]:
    """The runs of ``RUN,RUN[,...]`` (at least two) and the seeds they recorded; ``ap.error``
    when fewer are given or two recorded the same seed."""
    runs = [Path(p) for p in text.split(",") if p]
    if len(runs) < 2:
        ap.error("give at least two runs")
    seeds = [run_seed(r) for r in runs]
    if None not in seeds and len(set(seeds)) < len(seeds):
        ap.error(f"two runs share a seed ({seeds})")
    return runs, seeds


def same_frames(ap: argparse.ArgumentParser, frames_of: Mapping) -> list[str]:
    """The sorted frames of ``frames_of`` (``{run: frame ids it holds}``, the first run first);
    ``ap.error`` unless every run holds the same ones (per-seed counts compare the same cars)."""
    (first, frames), *_ = frames_of.items()
    for r, held in frames_of.items():
        if set(held) != set(frames):
            ap.error(f"{r} holds {len(set(held))} frames and {first} {len(set(frames))}, not the same ones")
    return sorted(frames)


def chosen_variants(ap: argparse.ArgumentParser, held: Sequence, asked: Sequence[str] | None) -> list[str]:
    """``asked`` (default: the variants every run holds, sorted), each checked to be in every
    one of ``held`` (each run's variants); ``ap.error`` otherwise."""
    common = set.intersection(*(set(h) for h in held))
    for v in asked or ():
        if v not in common:
            ap.error(f"--variant {v}: not in every run (common: {', '.join(sorted(common)) or 'none'})")
    return list(asked) if asked else sorted(common)


def car_rows(table: Mapping[str, np.ndarray]) -> dict[tuple[str, int], tuple[bool, bool, float]]:
    """``{(frame, label index): (within 1 m, IoU > 0.7, 3D IoU)}`` of one run's true positives
    (a :func:`bench_error_budget.car_table`)."""
    return {(str(f), int(g)): (bool(loc), bool(iou_ok), float(iou))
            for f, g, loc, iou_ok, iou in zip(table["frame"], table["gt_index"], table["pass_loc"],
                                             table["pass_iou"], table["iou"])}


def sign_test(gained: int, lost: int) -> float:
    """Two-sided p-value of ``gained`` against ``lost`` under no difference (1.0 when both are 0)."""
    from scipy.stats import binomtest

    n = gained + lost
    return 1.0 if n == 0 else float(binomtest(gained, n, 0.5).pvalue)


def _seed_figures(rows: Sequence[dict], keep) -> dict[str, list]:
    """Per seed: true positives, cars passing each test, mean 3D IoU, over the cars ``keep`` admits."""
    out = {"true positives": [], "mean IoU": []}
    out.update({t: [] for t in TESTS})
    for run in rows:
        cars = [v for k, v in run.items() if keep(k)]
        out["true positives"].append(len(cars))
        out["within 1 m"].append(sum(c[0] for c in cars))
        out["IoU > 0.7"].append(sum(c[1] for c in cars))
        out["mean IoU"].append(float(np.mean([c[2] for c in cars])) if cars else float("nan"))
    return out


def _hits(rows: Sequence[dict], keys: Sequence, col: int) -> np.ndarray:
    """``(len(keys),)``: at how many of the runs ``rows`` each car passes test ``col`` (0: 1 m, 1: IoU)."""
    return np.array([[r[k][col] for k in keys] for r in rows], bool).sum(0) if keys else np.zeros(0, int)


def _stability(rows: Sequence[dict], keys: Sequence) -> dict[str, dict[str, int]]:
    """Of ``keys`` (true positives in every run), those passing each test at every seed, some, none."""
    out = {}
    for t, col in zip(TESTS, (0, 1)):
        hits = _hits(rows, keys, col)
        out[t] = {"every seed": int((hits == len(rows)).sum()), "some seeds": int(((hits > 0) & (hits < len(rows))).sum()),
                  "no seed": int((hits == 0).sum())}
    return out


def _paired(rows_a: Sequence[dict], rows_b: Sequence[dict], keys: Sequence) -> dict[str, dict]:
    """Per test, over ``keys``: the cars, the passes summed over the seeds of A and of B, and
    the cars B passes at more seeds than A and at fewer, with the sign test of those two."""
    out = {}
    for t, col in zip(TESTS, (0, 1)):
        ha, hb = _hits(rows_a, keys, col), _hits(rows_b, keys, col)
        more, fewer = int((hb > ha).sum()), int((hb < ha).sum())
        out[t] = {"cars": len(keys), "passes": [int(ha.sum()), int(hb.sum())], "B more": more, "B fewer": fewer,
                  "p": sign_test(more, fewer)}
    return out


def compare(runs_a: Sequence[Mapping], runs_b: Sequence[Mapping], fold_of: Mapping[str, int], *,
            classes: Mapping[str, set] | None = None) -> dict:
    """Setting A against B over paired seeds, per fold group (module docstring).

    Parameters
    ----------
    runs_a, runs_b : sequences of car tables
        One :func:`bench_error_budget.car_table` of one variant per seed; the k-th of each
        were fitted with the same seed.
    fold_of : mapping
        ``{frame id: fold}`` for every frame the tables hold.
    classes : mapping, optional
        ``{class name: set of (frame, label index)}`` (e.g. distance bands): the car-by-car
        counts again within each class.

    Returns
    -------
    dict
        ``{group: {"seeds": {figure: {"A": [...], "B": [...]}}, "summed": {figure: [A, B]},
        "B ahead / level / behind": {figure: [n, n, n]}, "stability": {"A": ..., "B": ...},
        "paired": {test: {"cars", "passes", "B more", "B fewer", "p"}},
        "by class": {class: {test: ...}}}}`` (``"by class"`` with ``classes`` only).
    """
    if len(runs_a) != len(runs_b) or not runs_a:
        raise ValueError(f"the settings need the same number of seeds, at least one: {len(runs_a)} and {len(runs_b)}")
    rows_a, rows_b = [car_rows(t) for t in runs_a], [car_rows(t) for t in runs_b]
    report = {}
    for name, folds in GROUPS.items():
        def keep(key, folds=folds):
            return fold_of[key[0]] in folds

        fig_a, fig_b = _seed_figures(rows_a, keep), _seed_figures(rows_b, keep)
        group = {"seeds": {k: {"A": fig_a[k], "B": fig_b[k]} for k in fig_a}, "summed": {}, "B ahead / level / behind": {}}
        for k in fig_a:
            a, b = np.array(fig_a[k], float), np.array(fig_b[k], float)
            group["summed"][k] = [float(a.mean()), float(b.mean())] if k == "mean IoU" else [int(a.sum()), int(b.sum())]
            group["B ahead / level / behind"][k] = [int((b > a).sum()), int((b == a).sum()), int((b < a).sum())]
        every = {}
        for label, rows in (("A", rows_a), ("B", rows_b)):
            every[label] = sorted(k for k in set.intersection(*(set(r) for r in rows)) if keep(k))
        group["stability"] = {label: _stability(rows, every[label]) for label, rows in (("A", rows_a), ("B", rows_b))}
        both = sorted(set(every["A"]) & set(every["B"]))
        group["paired"] = _paired(rows_a, rows_b, both)
        if classes is not None:
            group["by class"] = {c: _paired(rows_a, rows_b, [k for k in both if k in members])
                                 for c, members in classes.items()}
        report[name] = group
    return report


def format_report(variant: str, report: dict, names: tuple[str, str]) -> str:
    """The printed form of one variant's :func:`compare`."""
    a, b = names
    lines = [f"## {variant}: {a} -> {b}, {len(report['all']['seeds']['true positives']['A'])} seeds"]
    for group, g in report.items():
        lines.append(f"{group}:")
        for k, (sa, sb) in g["summed"].items():
            per = ", ".join(f"{x:.3f} -> {y:.3f}" if k == "mean IoU" else f"{x} -> {y}"
                            for x, y in zip(g["seeds"][k]["A"], g["seeds"][k]["B"]))
            total = f"mean {sa:.4f} -> {sb:.4f}" if k == "mean IoU" else f"summed {sa} -> {sb} ({sb - sa:+d})"
            ahead, level, behind = g["B ahead / level / behind"][k]
            lines.append(f"  {k}: {total}; {b} ahead / level / behind at {ahead} / {level} / {behind} seeds; "
                         f"per seed {per}")
        for t, p in g["paired"].items():
            st = " | ".join(f"{label}: every seed {s[t]['every seed']}, some {s[t]['some seeds']}, none {s[t]['no seed']}"
                            for label, s in g["stability"].items())
            lines.append(f"  {t}, car by car ({p['cars']} cars true positives in every run): {b} passes more seeds for "
                         f"{p['B more']}, fewer for {p['B fewer']} (sign test p = {p['p']:.3f}); {st}")
        for c, by_test in g.get("by class", {}).items():
            lines.append(f"    {c}: " + "; ".join(
                f"{t} {q['cars']} cars, passes {q['passes'][0]} -> {q['passes'][1]}, {b} more / fewer "
                f"{q['B more']} / {q['B fewer']}" for t, q in by_test.items()))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (module docstring); ``argv`` as for :meth:`argparse.ArgumentParser.parse_args`."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("settings", nargs=2, metavar="NAME=RUN,RUN[,...]",
                    help="two settings, each its bench_real_folds.py --out directories in seed order")
    ap.add_argument("--root", required=True, help="the KITTI root the runs were fitted on (calibrations)")
    ap.add_argument("--variant", action="append", help="variants to compare (default: those every run holds)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    settings = {}
    for item in args.settings:
        name, sep, paths = item.partition("=")
        if not sep or not name or not paths:
            ap.error(f"{item!r}: expected NAME=RUN,RUN[,...]")
        if name in settings:
            ap.error(f"setting name {name!r} given twice")
        settings[name] = [Path(p) for p in paths.split(",") if p]
    (name_a, runs_a), (name_b, runs_b) = settings.items()
    if len(runs_a) != len(runs_b):
        ap.error(f"{name_a} has {len(runs_a)} runs and {name_b} {len(runs_b)}: pair them by seed")
    for ra, rb in zip(runs_a, runs_b):
        sa, sb = run_seed(ra), run_seed(rb)
        if sa is not None and sb is not None and sa != sb:
            ap.error(f"{ra} was fitted with seed {sa} and {rb}, its pair, with seed {sb}")
    dataset = KittiDataset(args.root)
    tables, frames_of = {}, {}
    for name, runs in settings.items():
        tables[name] = []
        for r in runs:
            records, _, by_variant = run_tables(r, dataset, camera_height=KITTI_CAMERA_HEIGHT)
            tables[name].append(by_variant)
            frames_of[r] = {f.frame_id for rs in records.values() for f in rs}
    frames = same_frames(ap, frames_of)
    variants = chosen_variants(ap, [t for ts in tables.values() for t in ts], args.variant)
    drive_of = frame_drives()
    missing = sorted(f for f in frames if f not in drive_of)
    if missing:
        ap.error(f"frame {missing[0]} has no drive in wirescene's drive map")
    fold_of = {f: DRIVE_FOLDS[drive_of[f]] for f in frames}
    out = {}
    for v in variants:
        first = tables[name_a][0][v]
        keys = list(zip(map(str, first["frame"]), map(int, first["gt_index"])))
        classes = {c: {k for k, m in zip(keys, mask) if m} for c, mask in group_masks(first).items() if c != "all"}
        out[v] = compare([t[v] for t in tables[name_a]], [t[v] for t in tables[name_b]], fold_of, classes=classes)
        print(format_report(v, out[v], (name_a, name_b)))
    if args.json:
        write_json(args.json, {"settings": {n: [str(r) for r in rs] for n, rs in settings.items()}, "variants": out})
        print(f"json: {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
