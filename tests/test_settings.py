"""One mapping of option names: the named options, ``--set`` and the API's ``settings``."""

from __future__ import annotations

import numpy as np
import pytest

from wirescene.core.errors import ArgumentError
from wirescene.core.settings import exposed_fields, parse_assignment, parse_value, replace_fields
from wirescene.fitting.pipeline import STAGES, FitOptions
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
    from wirescene.fitting.pipeline import PredetectOptions

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
