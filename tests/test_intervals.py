"""Bootstrap intervals clustered by drive (wirescene.eval.intervals)."""

import numpy as np
import pytest

from conftest import assert_close
from wirescene.core.labels import Label
from wirescene.eval.intervals import (
    bootstrap_weights,
    clustered_margin,
    clustered_share,
    format_intervals,
    kitti_intervals,
    kitti_run_intervals,
    kitti_variant_intervals,
    localisation_intervals,
    margin_intervals,
    percentile_interval,
)
from wirescene.eval.kitti_metrics import kitti_metrics
from wirescene.eval.metrics import EvaluationReport, TPRecord


def test_the_draws_do_not_depend_on_the_chunks():
    drawn = np.concatenate(list(bootstrap_weights(24, 2500, seed=7)))
    assert drawn.shape == (2500, 24)
    whole = np.random.default_rng(7).multinomial(24, np.full(24, 1 / 24), size=2500)
    assert_close(drawn, whole.astype(float), atol=0)


def test_a_share_the_drives_agree_on_has_no_spread_and_one_they_split_has_much():
    share, interval = clustered_share([5, 5, 5], [10, 10, 10], n_boot=500)
    assert_close(share, 50.0)
    assert_close(np.array(interval), np.array([50.0, 50.0]))
    # the same 15 of 30 cars, all passing on one drive and none on two: other drives could show 0% or 100%
    share, (lo, hi) = clustered_share([10, 0, 5], [10, 10, 10], n_boot=2000)
    assert_close(share, 50.0)
    assert lo <= 20.0 and hi >= 80.0
    # a drive of many cars weighs as its cars: the pooled share, not the mean of the drives' shares
    share, _ = clustered_share([1, 30], [10, 40], n_boot=0)
    assert_close(share, 62.0)


def test_bad_counts_are_refused():
    with pytest.raises(ValueError, match="one shape"):
        clustered_share([1, 2], [3], n_boot=10)
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clustered_share([4], [3], n_boot=10)
    with pytest.raises(ValueError, match="at least one cluster"):
        next(bootstrap_weights(0, 10))
    with pytest.raises(ValueError, match="no finite"):
        percentile_interval([np.nan])
    assert clustered_share([0], [0], n_boot=10)[1] is None


def _report(errors_by_frame):
    records = [TPRecord(frame, i, i, 0.9, err, 1.0, 1.0, True, None, 0)
               for frame, errors in errors_by_frame.items() for i, err in enumerate(errors)]
    return EvaluationReport(metrics={}, records=records, occlusion_source="kitti_flag", viewpoint_check="applied")


def test_localisation_intervals_group_frames_by_drive_and_others_alone():
    report = _report({"a1": [0.2, 3.0], "a2": [0.5], "b1": [2.0], "x": [0.1, 0.4]})
    out = localisation_intervals({"full": report}, {"a1": "A", "a2": "A", "b1": "B"}, n_boot=300)["full"]
    assert out["true_positives"] == 6 and out["drives"] == 2 and out["frames_alone"] == 1
    assert_close(out["share"], 100.0 * 4 / 6)
    lo, hi = out["interval"]
    assert lo < out["share"] < hi
    # a tighter threshold counts fewer cars; a variant without true positives has no share
    assert_close(localisation_intervals({"v": report}, {}, threshold=0.3, n_boot=0)["v"]["share"], 100.0 * 2 / 6)
    empty = localisation_intervals({"v": _report({})}, {}, n_boot=100)["v"]
    assert empty["share"] is None and empty["interval"] is None and empty["drives"] == empty["frames_alone"] == 0
    assert "-" in format_intervals({"v": empty}) and "2 drives and 1 frame of no known drive" in format_intervals({"full": out})


def _car(x, *, score=None, dz=0.0):
    return Label("Car", 0.0, 0, 0.0, [100.0 + 200 * x, 100.0, 200.0 + 200 * x, 200.0], [1.5, 1.6, 3.9],
                 [4.0 * x, 1.6, 20.0 + dz], 0.0, score)


def _two_drives():
    """``(ids, gts, exact, half, drives)``: 60 one-car frames, 30 on drive A and 30 on B; ``exact``
    places every car, ``half`` places drive B's 2 m too far (no 3D match)."""
    ids = [f"{i:06d}" for i in range(60)]
    gts = [[_car(0)] for _ in ids]
    exact = [[_car(0, score=0.9)] for _ in ids]
    half = [[_car(0, score=0.9, dz=0.0 if i < 30 else 2.0)] for i in range(60)]
    drives = {f: ("A" if i < 30 else "B") for i, f in enumerate(ids)}
    return ids, gts, exact, half, drives


def test_kitti_intervals_ranked_again_in_every_draw():
    # drive A: 30 frames whose car is found exactly; drive B: 30 whose estimate stands 2 m too far (no 3D match)
    ids, gts, _, preds, drives = _two_drives()
    out = kitti_intervals(gts, preds, ids, drives, n_boot=400, seed=1)
    point = kitti_metrics(gts, preds)["car"]["3d"]["moderate"]
    lo, hi = out["car"]["3d"]
    assert lo <= point <= hi and lo < 10.0 and hi > 90.0  # two drives that disagree: anything between
    assert_close(np.array(out["car"]["2d"]), np.array([100.0, 100.0]))  # every box is right on both drives
    assert out["drives"] == 2 and out["frames_alone"] == 0 and out["draws"] == 400 and out["difficulty"] == "moderate"
    # one drive of 60 frames that agree: no spread
    same = kitti_intervals(gts, preds[:30] * 2, ids, {f: "A" for f in ids}, n_boot=50)
    assert_close(np.array(same["iou_0.5"]["car"]["3d"]), np.array([100.0, 100.0]))
    # frames of no known drive are drawn alone: 60 draws of one frame make a narrower interval than two drives
    alone = kitti_intervals(gts, preds, ids, {}, n_boot=400, seed=1)
    assert alone["drives"] == 0 and alone["frames_alone"] == 60
    assert alone["car"]["3d"][1] - alone["car"]["3d"][0] < hi - lo


def test_kitti_margins_draw_the_same_drives_for_both():
    # the reference misses every car of drive B, the variant none: the variant's margin is positive in every draw
    # that holds drive B, and its AP margin interval is one-sided
    ids, gts, exact, half, drives = _two_drives()
    spread, margins = kitti_variant_intervals(gts, {"half": half, "exact": exact}, ids, drives, reference="half",
                                              n_boot=400, seed=1)
    out = margins["exact"]
    lo, hi = out["car"]["3d"]
    assert list(margins) == ["exact"] and out["margin_over"] == "half" and lo >= 0.0 and hi > 50.0
    assert_close(np.array(out["car"]["2d"]), np.array([0.0, 0.0]))  # the same 2D boxes
    # each name's own intervals are those kitti_intervals gives it alone
    assert spread["half"] == kitti_intervals(gts, half, ids, drives, n_boot=400, seed=1)
    with pytest.raises(ValueError, match="prediction frames of exact"):
        kitti_variant_intervals(gts, {"half": half, "exact": exact[:10]}, ids, drives, n_boot=10)
    with pytest.raises(ValueError, match="reference"):
        kitti_variant_intervals(gts, {"exact": exact}, ids, drives, reference="half", n_boot=10)


def test_kitti_intervals_over_runs_take_one_run_per_draw():
    # two runs of the same 60 frames on two drives: one places every car, the other misses drive B's in 3D
    ids, gts, exact, half, drives = _two_drives()
    out = kitti_run_intervals(gts, [exact, half], ids, drives, n_boot=400, seed=1)
    lo, hi = out["car"]["3d"]
    # draws of the exact run are all 100; draws of the other run spread as that run's drive interval does
    assert hi == 100.0 and lo <= kitti_intervals(gts, half, ids, drives, n_boot=400, seed=1)["car"]["3d"][1]
    assert lo < 50.0 and out["runs"] == 2 and out["drives"] == 2 and out["draws"] == 400
    # one run alone is that run's interval over drives, draw for draw
    alone = kitti_run_intervals(gts, [half], ids, drives, n_boot=400, seed=1)
    assert {k: v for k, v in alone.items() if k != "runs"} == kitti_intervals(gts, half, ids, drives, n_boot=400,
                                                                               seed=1)
    # two identical runs: the same as one
    assert kitti_run_intervals(gts, [exact, exact], ids, drives, n_boot=50)["car"]["3d"] == [100.0, 100.0]
    with pytest.raises(ValueError, match="run 1"):
        kitti_run_intervals(gts, [exact, half[:10]], ids, drives, n_boot=10)
    with pytest.raises(ValueError, match="no run"):
        kitti_run_intervals(gts, [], ids, drives, n_boot=10)


def test_kitti_intervals_refuse_mismatches_and_say_none_where_kitti_has_no_figure():
    ids = ["000001"]
    with pytest.raises(ValueError, match="frame ids"):
        kitti_intervals([[_car(0)]], [[_car(0, score=0.5)]], ["a", "b"], {})
    with pytest.raises(ValueError, match="difficulty"):
        kitti_intervals([[_car(0)]], [[_car(0, score=0.5)]], ids, {}, difficulty="medium")
    no_alpha = Label("Car", 0.0, 0, -10.0, [100.0, 100.0, 200.0, 200.0], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.5)
    out = kitti_intervals([[_car(0)]], [[no_alpha]], ids, {}, n_boot=20)
    assert out["car"]["aos"] is None and out["car"]["3d"] is not None
    empty = kitti_intervals([], [], [], {}, n_boot=20)
    assert empty["car"]["3d"] is None and empty["drives"] == 0


def test_a_margin_draws_the_same_drives_for_both_variants():
    # the same cars on two drives, each variant better on one: shares swing with the draw, their margin is paired
    margin, (lo, hi) = clustered_margin([9, 1], [10, 10], [8, 0], [10, 10], n_boot=1000)
    assert_close(margin, 10.0)
    assert_close(np.array([lo, hi]), np.array([10.0, 10.0]))  # +1 car of 10 on each drive: +10 points in every draw
    margin, (lo, hi) = clustered_margin([10, 0], [10, 10], [5, 5], [10, 10], n_boot=1000)
    assert_close(margin, 0.0)
    assert lo <= -40.0 and hi >= 40.0  # +50 on one drive, -50 on the other
    margin, interval = clustered_margin([0], [0], [0], [1], n_boot=10)  # no car of the variant: no margin
    assert np.isnan(margin) and interval is None
    with pytest.raises(ValueError, match="one shape"):
        clustered_margin([1, 2], [3, 3], [1], [3], n_boot=0)
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clustered_margin([1], [0], [0], [1], n_boot=0)


def test_margin_intervals_over_a_reference_and_formatted():
    good = _report({"a1": [0.2, 0.3], "b1": [0.4, 2.0]})
    base = _report({"a1": [0.2, 3.0], "b1": [0.4, 2.0]})
    margins = margin_intervals({"coarse+gp": base, "full": good}, {"a1": "A", "b1": "B"}, reference="coarse+gp",
                               n_boot=500)
    assert list(margins) == ["full"] and margins["full"]["reference"] == "coarse+gp"
    assert_close(margins["full"]["margin"], 25.0)
    lo, hi = margins["full"]["interval"]
    assert lo == 0.0 and hi == 50.0  # drive A twice: +50; drive B twice: 0
    shares = localisation_intervals({"coarse+gp": base, "full": good}, {"a1": "A", "b1": "B"}, n_boot=100)
    text = format_intervals(shares, margins=margins)
    assert "Margins over coarse+gp" in text and "+25.0 [+0.0, +50.0]" in text
    with pytest.raises(ValueError, match="reference"):
        margin_intervals({"full": good}, {}, reference="coarse+gp")


def test_the_true_positives_of_one_drive_get_no_interval_over_drives():
    """Every draw of one drive is that drive: its [x, x] read as a share known exactly, and "1 drives"."""
    good = _report({"a1": [0.2, 0.3], "a2": [0.4, 2.0]})
    base = _report({"a1": [0.2, 3.0], "a2": [0.4, 2.0]})
    reports, drives = {"coarse+gp": base, "full": good}, {"a1": "A", "a2": "A"}
    text = format_intervals(localisation_intervals(reports, drives, n_boot=100),
                            margins=margin_intervals(reports, drives, reference="coarse+gp", n_boot=100))
    assert "75.0% (no interval: one drive) of 4 true positives, 1 drive\n" in text
    assert "  full       +25.0" in text and "[+" not in text and "1 drives" not in text


def test_kitti_intervals_of_one_drive_are_said_to_be_none():
    """The KITTI APs' interval over one drive was printed [x, x] "over 1 drives": it says there is none."""
    from wirescene.eval.kitti_metrics import ONE_DRIVE, format_kitti_intervals, format_kitti_summary

    car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    ids = [f"{i:06d}" for i in range(10)]
    spread = kitti_intervals([[car]] * 10, [[car]] * 10, ids, dict.fromkeys(ids, "drive_1"), n_boot=20)
    assert format_kitti_intervals({"full": spread}) == ONE_DRIVE
    point = {"full": kitti_metrics([[car]] * 10, [[car]] * 10), "base": kitti_metrics([[car]] * 10, [[]] * 10)}
    spreads, margins = kitti_variant_intervals([[car]] * 10, {"full": [[car]] * 10, "base": [[]] * 10}, ids,
                                               dict.fromkeys(ids, "drive_1"), reference="base", n_boot=20)
    summary = format_kitti_summary(point, intervals=spreads, margins=margins)
    assert summary.count(ONE_DRIVE) == 1 and "in 10 frames" in summary  # once for the APs and their margins
    two = kitti_intervals([[car]] * 10, [[car]] * 10, ids, {f: f"drive_{f < '000005'}" for f in ids}, n_boot=20)
    assert "over 2 drives" in format_kitti_intervals({"full": two})


def test_a_margin_over_drives_of_the_reference_keeps_its_interval():
    """A margin's draws take the drives of either variant's true positives: its interval was hidden where the variant's
    own were of one drive, though the reference's two drives moved it (+25.0 printed without its [+25.0, +50.0])."""
    good = _report({"a1": [0.2, 0.3]})
    base = _report({"a1": [0.2, 3.0], "b1": [0.4, 0.4]})
    reports, drives = {"coarse+gp": base, "full": good}, {"a1": "A", "b1": "B"}
    margins = margin_intervals(reports, drives, reference="coarse+gp", n_boot=200)
    assert margins["full"]["drives"] == 2 and margins["full"]["frames_alone"] == 0
    text = format_intervals(localisation_intervals(reports, drives, n_boot=200), margins=margins)
    assert "100.0% (no interval: one drive) of 2 true positives, 1 drive\n" in text
    assert text.endswith("  full       +25.0 [+25.0, +50.0]")
    alone = format_intervals(localisation_intervals({"full": _report({"x": [0.2, 3.0]})}, {}, n_boot=50))
    assert "(no interval: one frame) of 2 true positives, 0 drives and 1 frame of no known drive" in alone


def test_kitti_intervals_of_several_runs_on_one_drive_keep_the_runs_spread():
    """Each draw of several runs takes one at random: on one drive their spread is an interval still, not none."""
    from wirescene.eval.kitti_metrics import ONE_DRIVE, format_kitti_intervals

    car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    miss = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 25.0], 0.0, 0.9)
    ids = [f"{i:06d}" for i in range(10)]
    spread = kitti_run_intervals([[car]] * 10, [[[car]] * 10, [[miss]] * 10], ids, dict.fromkeys(ids, "d1"),
                                 n_boot=40)
    lo, hi = spread["car"]["3d"]
    assert lo < hi  # the run that misses every car, or the one that finds them
    text = format_kitti_intervals({"2 runs": spread})
    assert text != ONE_DRIVE and "over 1 drive," in text and f"[{lo:.1f}, {hi:.1f}]" in text


def test_the_report_gives_no_interval_over_one_drive():
    """The report's tables gave the [x, x] of one drive that the printed lines say is none."""
    from wirescene.eval.report import _kitti_table, _metrics_table

    good = _report({"a1": [0.2, 0.3], "a2": [0.4, 2.0]})
    good = EvaluationReport({"all": {}}, good.records, "kitti_flag", "applied")  # the table's other figures: none
    one = localisation_intervals({"full": good}, {"a1": "A", "a2": "A"}, n_boot=50)
    assert "[75, 75]%" not in _metrics_table({"full": good}, one)
    two = localisation_intervals({"full": good}, {"a1": "A", "a2": "B"}, n_boot=50)
    assert "[50, 100]%" in _metrics_table({"full": good}, two)
    car = Label("Car", 0.0, 0, 0.0, [100, 100, 200, 200], [1.5, 1.6, 3.9], [0.0, 1.6, 20.0], 0.0, 0.9)
    ids = [f"{i:06d}" for i in range(10)]
    point = {"full": kitti_metrics([[car]] * 10, [[car]] * 10)}
    spread = {"full": kitti_intervals([[car]] * 10, [[car]] * 10, ids, dict.fromkeys(ids, "d1"), n_boot=20)}
    table = _kitti_table(point, spread)
    assert "[22.5, 22.5]" not in table and "bootstrap interval" not in table  # 9 of 10 cars: at most 22.5
    spread = {"full": kitti_intervals([[car]] * 10, [[car]] * 10, ids, {f: f"d{f < '000005'}" for f in ids}, n_boot=20)}
    assert "22.5 [22.5, 22.5]" in _kitti_table(point, spread)
