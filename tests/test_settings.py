"""One mapping of option names: the named options, ``--set`` and the API's ``settings``."""

from __future__ import annotations

import numpy as np
import pytest

from wirescene.core.errors import ArgumentError
from wirescene.core.settings import exposed_fields, parse_assignment, parse_value, replace_fields
from wirescene.fitting.options import STAGES, FitOptions
from wirescene.infer.inference import InferenceOptions
from wirescene.lift import LiftingOptions


def test_parse_value_follows_the_default_type():
    assert parse_value("3", 1.0) == 3.0 and isinstance(parse_value("3", 1.0), float)
    assert parse_value("3", 1) == 3 and isinstance(parse_value("3", 1), int)
    assert parse_value("TRUE", False) is True and parse_value("0", True) is False
    with pytest.raises(ValueError, match="expected 0, 1, true or false"):
        parse_value("yes", True)
    with pytest.raises(ValueError):
        parse_value("x", 1.0)


def test_parse_assignment_needs_scope_key_and_value():
    assert parse_assignment("inference.box_weight=5") == ("inference", "box_weight", "5")
    for bad in ("box_weight=5", "inference.box_weight", ".x=1", "inference.=1"):
        with pytest.raises(ValueError, match="SCOPE.KEY=VALUE"):
            parse_assignment(bad)


def test_replace_fields_checks_names_and_keeps_the_rest():
    base = InferenceOptions()
    out = replace_fields(base, {"box_weight": "7", "plane_refinement": "0", "iterations": 3})
    assert (out.box_weight, out.plane_refinement, out.iterations) == (7.0, False, 3)
    assert out.size_prior == base.size_prior and base.box_weight == 100.0  # a copy, the defaults untouched
    assert isinstance(replace_fields(LiftingOptions(), {"road_prior": 0}).road_prior, float)
    with pytest.raises(ValueError, match="no option 'box_wieght'.*box_weight"):
        replace_fields(base, {"box_wieght": 1})


def test_every_number_of_the_stage_options_is_checked_against_its_kind_and_limits():
    options = FitOptions()
    assert options.checked() is options  # the defaults pass
    for setting, says in (({"lifting.n_particles": 0}, "at least 1"), ({"lifting.n_particles": 2.0}, "an integer"),
                          ({"lifting.n_particles": True}, "an integer"), ({"inference.size_prior": "inf"}, "finite"),
                          ({"inference.size_prior": None}, "a finite number"),
                          ({"inference.keep_fraction": 1.01}, "at most 1"),
                          ({"lifting.azimuth_halfwidth": 181}, "at most 180"),
                          ({"inference.flip_evidence": 0}, "true or false"), ({"predetect.box_weight": -1}, "at least 0")):
        with pytest.raises(ValueError, match=says):
            options.with_settings(setting)
    assert options.with_settings({"lifting.n_particles": np.int64(7)}).lifting.n_particles == 7
    assert options.with_settings({"inference.flip_evidence": np.bool_(False)}).inference.flip_evidence is not True
    assert options.with_settings({"inference.known_occluded_score": 0.5}).inference.known_occluded_score == 0.5
    with pytest.raises(ArgumentError, match="^options: lifting.camera_height must be at least 0.1, got 0.0"):
        FitOptions(lifting=LiftingOptions(camera_height=0.0)).checked()
    with pytest.raises(ArgumentError, match="^options: seed must be a non-negative integer"):
        FitOptions(seed=1.5).checked()


def test_the_coarse_grid_is_bounded_in_planes_whatever_step_is_refined():
    """One check on the plane grid's size (pitches x rolls), not per step: the finest steps
    over the default ranges pass, and so does either step refined alone; more than
    MAX_GRID_PLANES planes is a ValueError naming the four options."""
    from wirescene.lift import MAX_GRID_PLANES

    options = FitOptions()
    finest = options.with_settings({"lifting.pitch_step": 0.01, "lifting.roll_step": 0.01}).lifting
    assert len(finest.plane_grid()[0]) == 601 * 301 <= MAX_GRID_PLANES and LiftingOptions().combined_problem() is None
    assert options.with_settings({"lifting.pitch_range": 45, "lifting.pitch_step": 0.01}).lifting.pitch_step == 0.01
    names = "lifting.pitch_range, lifting.pitch_step, lifting.roll_range, lifting.roll_step"
    with pytest.raises(ValueError, match=f"^{names} give 601 pitches x 601 rolls = 361,201 ground planes, "
                                         "at most 250,000: take coarser steps or narrower ranges$"):
        options.with_settings({"lifting.pitch_step": 0.01, "lifting.roll_step": "0.01", "lifting.roll_range": 3})
    with pytest.raises(ValueError, match=r"give 8e\+300 pitches x 13 rolls"):  # counted, never built
        options.with_settings({"lifting.pitch_range": 1e300})
    with pytest.raises(ArgumentError, match=f"^options: {names} give 2,001 pitches"):  # options built directly
        FitOptions(lifting=LiftingOptions(pitch_range=10, pitch_step=0.01, roll_step=0.01)).checked()
    with pytest.raises(ArgumentError, match="pitch_step must be at least 0.01"):  # a bad step: its own message
        FitOptions(lifting=LiftingOptions(pitch_step=0.0)).checked()


def test_particles_and_samples_are_bounded_together_and_the_azimuths_alone():
    """The fine stage's memory grows with particles x samples (the particles the plane grid
    holds): at most MAX_HYPOTHESES, wherever the options come from; the particles alone at
    most MAX_PARTICLES, and the coarse grid's azimuths MAX_AZIMUTH_STEPS a detection and
    MAX_GRID_CELLS (plane, azimuth) cells, what the plane cap allows at the default azimuths."""
    import wirescene
    from conftest import KITTI_ROOT
    from wirescene.lift import MAX_AZIMUTH_STEPS, MAX_GRID_CELLS, MAX_HYPOTHESES, MAX_PARTICLES

    options = FitOptions()
    # the default grid's 325 planes: more particles cost nothing more
    assert options.with_settings({"lifting.n_particles": MAX_PARTICLES, "inference.samples": 150}).lifting.n_particles \
        == MAX_PARTICLES and 325 * 150 <= MAX_HYPOTHESES
    with pytest.raises(ValueError, match="^lifting.n_particles must be at most 25000, got 25001$"):
        options.with_settings({"lifting.n_particles": MAX_PARTICLES + 1})
    with pytest.raises(ValueError, match=r"^lifting.n_particles x inference.samples = 1,573 \(one a plane of the "
                                         r"grid\) x 40 = 62,920 hypotheses a car and iteration, at most 50,000"):
        options.with_settings({"lifting.n_particles": 5000, "lifting.pitch_step": 0.05, "inference.samples": 40})
    with pytest.raises(ArgumentError, match=r"^options: lifting.n_particles x inference.samples = 1,500 x 40"):
        FitOptions(lifting=LiftingOptions(n_particles=1500, pitch_step=0.05), inference=InferenceOptions(samples=40)) \
            .checked()
    with pytest.raises(ArgumentError, match="^particles: must be at most 25,000, got 30000$"):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002"], particles=30_000)
    # azimuths: 0.1 deg round the circle at most, and no more cells than the finest plane grid at the default 72
    assert LiftingOptions(unknown_viewpoint_step=0.1).combined_problem() is None
    assert LiftingOptions(unknown_viewpoint_step=0.09).combined_problem() == (
        ("unknown_viewpoint_step",), "gives 4,000 azimuths a detection, at most 3,600: take a coarser step")
    names, problem = LiftingOptions(azimuth_halfwidth=90, azimuth_step=0.05).combined_problem()
    assert names == ("azimuth_halfwidth", "azimuth_step") and problem.startswith(f"give 3,601 azimuths a detection, "
                                                                                 f"at most {MAX_AZIMUTH_STEPS:,}")
    finest = dict(pitch_step=0.01, roll_step=0.01)
    assert LiftingOptions(**finest).combined_problem() is None and 180_901 * 72 <= MAX_GRID_CELLS
    with pytest.raises(ValueError, match=r"^lifting.pitch_step, lifting.roll_step, lifting.azimuth_halfwidth, "
                                         r"lifting.azimuth_step give 180,901 ground planes x 181 azimuths = 32,743,081 "
                                         r"cells a detection, at most 18,000,000"):
        options.with_settings({f"lifting.{k}": v for k, v in {**finest, "azimuth_step": 0.25}.items()})


def test_iterations_and_workers_are_bounded_alike_wherever_they_come_from():
    """The fine stage's iterations (some 0.3 s each an 8-car frame) and polish iterations at most
    MAX_ITERATIONS, the coarse stage's Levenberg-Marquardt steps at most MAX_LIFT_ITERATIONS (its
    damping overflowed from some 150 on): --set, the API's settings and FitOptions.checked refuse
    alike; the API's workers at most MAX_WORKERS (each a process of some 440 MB)."""
    import wirescene
    from conftest import KITTI_ROOT
    from wirescene.core.validate import MAX_WORKERS
    from wirescene.infer.inference import MAX_ITERATIONS
    from wirescene.lift import MAX_LIFT_ITERATIONS

    assert (MAX_ITERATIONS, MAX_LIFT_ITERATIONS) == (1000, 100) and MAX_WORKERS >= 64
    options = FitOptions()
    assert options.with_settings({"inference.iterations": 1000, "inference.polish_iterations": 1000,
                                  "lifting.iterations": 100}).lifting.iterations == 100
    for name, value, limit in (("inference.iterations", 1001, 1000), ("inference.polish_iterations", "5000", 1000),
                               ("lifting.iterations", 101, 100)):
        got = int(value)
        with pytest.raises(ValueError, match=f"^{name} must be at most {limit}, got {got}$"):
            options.with_settings({name: value})
    with pytest.raises(ArgumentError, match="^options: lifting.iterations must be at most 100, got 500$"):
        FitOptions(lifting=LiftingOptions(iterations=500)).checked()
    with pytest.raises(ArgumentError, match="^options: inference.polish_iterations must be at most 1000, got 2000$"):
        FitOptions(inference=InferenceOptions(polish_iterations=2000)).checked()
    with pytest.raises(ArgumentError, match="^settings: inference.iterations must be at most 1000, got 5000$"):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002"], settings={"inference.iterations": 5000})
    with pytest.raises(ArgumentError, match=f"^workers: must be at most {MAX_WORKERS:,} .*, got {MAX_WORKERS + 1}$"):
        wirescene.evaluate(KITTI_ROOT, variants="coarse", frames=["000002", "000010"], workers=MAX_WORKERS + 1)


def test_with_settings_reaches_every_stage_and_refuses_unknown_ones():
    out = FitOptions().with_settings({"inference.polish_samples": "6", "lifting.iterations": 2})
    assert out.inference.polish_samples == 6 and out.lifting.iterations == 2
    assert FitOptions().with_settings(None) == FitOptions()
    assert FitOptions().with_settings({"predetect.threshold": "0.5"}).predetect.threshold == 0.5
    with pytest.raises(ValueError, match="STAGE one of lifting, inference, predetect"):
        FitOptions().with_settings({"parts.n_trees": 3})
    with pytest.raises(ValueError, match="no option"):
        FitOptions().with_settings({"lifting.box_weight": 3})


def test_every_exposed_field_is_a_command_line_option_of_eval_fit_and_predict():
    from wirescene.cli.main import eval_cmd, fit_cmd, predict_cmd
    from wirescene.fitting.options import PredetectOptions

    stages = {"lifting": LiftingOptions, "inference": InferenceOptions, "predetect": PredetectOptions}
    assert set(stages) == set(STAGES)
    wanted = {f"{stage}__{f.name}": f"--{cli}" for stage, cls in stages.items() for f, cli, _ in exposed_fields(cls)}
    assert len(wanted) >= 11  # the options the commands had before they were generated
    for command in (eval_cmd, fit_cmd, predict_cmd):
        params = {p.name: p.opts for p in command.params}
        for name, flag in wanted.items():
            assert flag in params.get(name, []), (command.name, name)
        assert "settings" in params


def test_named_options_set_and_api_give_the_same_options():
    from wirescene.api import _options
    from wirescene.cli.main import _fit_options

    settings = {"inference.box_weight": 40.0, "lifting.road_prior": 0.5, "inference.polish_samples": 6}
    named = _fit_options(30, 2, inference__box_weight=40.0, lifting__road_prior=0.5,
                         settings=("inference.polish_samples=6",), device="numpy")
    by_set = _fit_options(30, 2, settings=tuple(f"{k}={v}" for k, v in settings.items()), device="numpy")
    api = _options(None, 30, 2, None, settings)
    assert named == by_set == api
    assert named.inference.box_weight == 40.0 and named.lifting.n_particles == 30


def test_named_option_wins_over_set():
    from wirescene.cli.main import _fit_options

    out = _fit_options(30, 0, inference__box_weight=5.0, settings=("inference.box_weight=9",))
    assert out.inference.box_weight == 5.0


def test_api_settings_errors_name_the_argument():
    import numpy as np

    import wirescene

    image = np.zeros((100, 200, 3), np.uint8)
    P = np.array([[700.0, 0, 100, 0], [0, 700, 50, 0], [0, 0, 1, 0]])
    with pytest.raises(ArgumentError, match="settings.*no option 'nope'"):
        wirescene.fit(image, P, [[50, 40, 120, 80]], settings={"inference.nope": 1})
    with pytest.raises(ArgumentError, match="settings"):
        wirescene.fit(image, P, [[50, 40, 120, 80]], settings=["inference.box_weight=1"])
    with pytest.raises(ArgumentError, match="^settings: lifting.pitch_range, lifting.pitch_step, lifting.roll_range, "
                                            "lifting.roll_step give 601 pitches x 601 rolls"):
        wirescene.fit(image, P, [[50, 40, 120, 80]], settings={"lifting.pitch_step": 0.01, "lifting.roll_step": 0.01,
                                                               "lifting.roll_range": 3})


def test_set_on_the_command_line_is_checked(tmp_path):
    from click.testing import CliRunner

    from wirescene.cli.main import main, sample_root

    frame = sample_root() / "training"
    for item, says in (("inference.nope=1", "no option 'nope'"), ("inference.box_weight=x", "box_weight"),
                       ("box_weight=1", "SCOPE.KEY=VALUE"), ("inference.samples=1", "at least 2"),
                       ("lifting.pitch_step=0", "lifting.pitch_step must be at least 0.01"),
                       ("inference.box_weight=nan", "finite")):
        r = CliRunner().invoke(main, ["fit", str(frame / "image_2" / "000010.png"), "--calib",
                                      str(frame / "calib" / "000010.txt"), "--out", str(tmp_path / "o"),
                                      "--set", item])
        assert r.exit_code == 2 and "--set" in r.output and says in r.output, (item, r.output)
        assert not (tmp_path / "o").exists()


@pytest.mark.skipif(not hasattr(__import__("os"), "sched_setaffinity"), reason="CPU affinity is Linux's")
def test_the_default_workers_are_the_cores_this_process_may_use():
    """A job scheduler's share of the machine (the CPU affinity), not the machine's every core."""
    import subprocess
    import sys

    code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
            "from wirescene.cli.options import workers_count; print(workers_count(None))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "1"
