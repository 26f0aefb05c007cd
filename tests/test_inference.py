import dataclasses

import numpy as np
import pytest

from conftest import KITTI_ROOT, assert_close
from wirescene.core.errors import ShapeError
from wirescene.core.groundplane import alpha_from_rotation_y
from wirescene.core.shape import load_default
from wirescene.core.types import Detections
from wirescene.core.viewpoints import angle_difference, bin_center, viewpoint_bin
from wirescene.fitting.options import FitOptions
from wirescene.fitting.pipeline import fit_scene
from wirescene.infer.inference import InferenceOptions, estimate_from_refined, refine_particles
from wirescene.infer.likelihood import GaussianVertexEvidence, instantiate_wireframes, object_likelihood
from wirescene.io.kitti import KittiDataset
from wirescene.lift import LiftingOptions, lift_table, road_angle, select_particles


def test_object_likelihood_matches_equation():
    e = np.array([[1.0, 2.0, -1.0, 4.0]])
    self_hidden = np.array([[False, False, False, True]])
    mask = np.array([[False, True, False, False]])
    # visible parts 0, 2 contribute 1 - 1; part 1 is masked -> c; part 3 self-occluded -> nothing;
    # normalised by the 3 non-self-occluded parts.
    assert_close(object_likelihood(e, self_hidden, mask, c=0.5), [(1.0 - 1.0 + 0.5) / 3])
    assert_close(object_likelihood(e, self_hidden, None, c=0.5), [(1.0 + 2.0 - 1.0) / 3])
    # All parts self-occluded: no division by zero.
    assert_close(object_likelihood(e, np.ones_like(self_hidden), None, c=0.5), [0.0])


@pytest.fixture(scope="module")
def synthetic_scene():
    """Four cars of random shapes on a pitched plane, seen by a real KITTI camera."""
    camera = KittiDataset(KITTI_ROOT).camera("000010")
    model = load_default()
    rng = np.random.default_rng(3)
    pitch, roll = np.deg2rad(0.7), np.deg2rad(-0.3)
    truth = dict(x=np.array([-4.0, 3.0, 6.0, -1.5]), z=np.array([11.0, 18.0, 27.0, 35.0]),
                 azimuth=np.array([0.4, -1.5, 1.7, 2.9]), shape=rng.standard_normal((4, 5)) * 0.8)
    b = instantiate_wireframes(camera, model, pitch=np.full(4, pitch), roll=np.full(4, roll), height=1.65, **truth)
    boxes = np.clip(np.concatenate([b.uv.min(1), b.uv.max(1)], 1), 0, [1241, 374, 1241, 374])
    alpha = alpha_from_rotation_y(truth["azimuth"], truth["x"], truth["z"])
    dets = Detections(boxes, 1.0, bin_center(viewpoint_bin(alpha)))
    evidence = GaussianVertexEvidence(b.uv, ~b.self_hidden)
    return camera, model, truth, dets, evidence


@pytest.mark.parametrize("prior", [0.0, None])
@pytest.mark.parametrize("shared", [True, False])
def test_inference_with_perfect_evidence_beats_coarse(synthetic_scene, shared, prior):
    """Perfect evidence of cars of random shapes: the fine stage beats its coarse start,
    with the default priors (chosen for the weak evidence of real part detectors) and
    without the shape prior."""
    camera, model, truth, dets, evidence = synthetic_scene
    # The boxes-only start (no road prior): what the fine stage's search adds is tested
    # here. With the road prior this scene's start is already within 0.42 m (median).
    lifted = lift_table(camera, dets, options=LiftingOptions(road_prior=0.0))
    particles = select_particles(lifted, shared_plane=shared, n_particles=30)
    coarse_err = np.hypot(particles.x[0] - truth["x"], particles.z[0] - truth["z"])
    coarse_az = angle_difference(particles.azimuth[0], truth["azimuth"])
    options = InferenceOptions(iterations=10) if prior is None else InferenceOptions(iterations=10, shape_prior=prior)
    refined = refine_particles(camera, particles, evidence, model, options=options, rng=np.random.default_rng(0))
    assert np.all(np.diff(refined.history) >= -1e-9)  # the objective never decreases
    est = estimate_from_refined(camera, refined, dets, model, variant="fg+gp" if shared else "fg")
    loc = np.array([o.location for o in est.objects])
    fine_err = np.hypot(loc[:, 0] - truth["x"], loc[:, 2] - truth["z"])
    fine_az = angle_difference([o.rotation_y for o in est.objects], truth["azimuth"])
    assert np.median(fine_err) < np.median(coarse_err)
    assert np.median(fine_az) < np.median(coarse_az)
    assert np.median(fine_az) < np.deg2rad(5)
    for o in est.objects:
        assert o.vertices.shape == (36, 3) and o.visibility.shape == (36,) and o.exemplar in model.exemplar_names


def test_fine_fit_on_real_frame_is_deterministic():
    ds = KittiDataset(KITTI_ROOT)
    labels = ds.labels("000002")
    from wirescene.io.detections import detections_from_labels

    dets = detections_from_labels(labels)
    opts = FitOptions(lifting=LiftingOptions(n_particles=10), inference=InferenceOptions(iterations=3, samples=6), seed=5)
    a = fit_scene(ds.camera("000002"), dets, variant="fg+gp", image=ds.image("000002"), options=opts)
    b = fit_scene(ds.camera("000002"), dets, variant="fg+gp", image=ds.image("000002"), options=opts)
    assert_close(a.objects[0].vertices, b.objects[0].vertices, atol=0)
    assert a.objects[0].shape.shape == (5,)
    h, w, l = a.objects[0].dims
    assert 1.0 < h < 2.0 and 1.3 < w < 2.2 and 3.0 < l < 5.5


def test_viewpoint_from_evidence_recovers_bins(synthetic_scene):
    from wirescene.infer.evidence import viewpoint_from_evidence

    camera, model, truth, dets, evidence = synthetic_scene
    unknown = Detections(dets.boxes, dets.scores, np.array([np.nan, dets.alpha[1], np.nan, np.nan]))
    out = viewpoint_from_evidence(camera, unknown, evidence, model)
    assert out.alpha[1] == dets.alpha[1]  # a known viewpoint is kept
    assert np.all(np.isfinite(out.alpha))
    assert np.all(angle_difference(out.alpha, dets.alpha) <= np.deg2rad(45) + 1e-9)


def _refine_twice(synthetic_scene, shared, first: dict, second: dict):
    """Algorithm 1 on the same 20 coarse particles with the same random numbers under two
    sets of options, for tests that compare a schedule with and without one step."""
    camera, model, truth, dets, evidence = synthetic_scene
    particles = select_particles(lift_table(camera, dets), shared_plane=shared, n_particles=20)
    return tuple(refine_particles(camera, particles, evidence, model, options=InferenceOptions(**opts),
                                  rng=np.random.default_rng(0)) for opts in (first, second))


@pytest.mark.parametrize("shared", [True, False])
def test_pruning_keeps_the_best_particles_and_never_loses_the_objective(synthetic_scene, shared):
    base = dict(iterations=6, samples=6, polish_iterations=0)
    full, pruned = _refine_twice(synthetic_scene, shared, dict(base, prune_after=0),
                                 dict(base, prune_after=2, keep_fraction=0.25))
    assert full.score.shape == (20, 4) and pruned.score.shape == (5, 4)
    assert np.all(np.diff(pruned.history) >= -1e-9)
    # Until the pruning step both runs are identical (same random numbers).
    assert_close(pruned.history[:3], full.history[:3], atol=0)
    # Uncoupled objects keep their own best particles (rows regrouped): each object's
    # best never falls below the scene-wise choice.
    if not shared:
        assert np.all(pruned.score.max(axis=0) >= pruned.score[pruned.best_scene()] - 1e-12)


@pytest.mark.parametrize("shared", [True, False])
def test_polish_refines_only_the_map_rows_and_never_loses_the_objective(synthetic_scene, shared):
    base = dict(iterations=6, samples=6, prune_after=2)
    plain, polished = _refine_twice(synthetic_scene, shared, dict(base, polish_iterations=0),
                                    dict(base, polish_iterations=6, polish_samples=12))
    assert polished.score.shape == (1, 4)
    assert np.all(np.diff(polished.history) >= -1e-9)
    # Same random numbers until the polish starts, then only the MAP rows go on.
    assert_close(polished.history[:7], plain.history, atol=0)
    rows = plain.best_rows()
    before = plain.score[rows, np.arange(4)]
    if not shared:  # independent objects: each one's own objective never decreases
        assert np.all(polished.score[0] >= before - 1e-9)
    assert polished.score[0].sum() > before.sum()  # 6 more iterations found a better scene


def test_best_rows_for_coupled_and_independent_objects():
    from wirescene.infer.inference import _best_rows

    score = np.array([[3.0, 0.0], [1.0, 5.0], [2.0, 1.0]])
    assert_close(_best_rows(score, 2, coupled=True), [[1, 1], [0, 0]], atol=0)  # scene sums 3, 6, 3
    assert_close(_best_rows(score, 2, coupled=False), [[0, 1], [2, 2]], atol=0)


class _Flat:
    """Evidence that says nothing: every hypothesis scores the same."""

    def log_ratio(self, uv, obj, scale):
        return np.zeros(np.shape(uv)[:-1])


def test_fine_road_prior_turns_cars_towards_the_road_where_evidence_is_silent(synthetic_scene):
    """With evidence that says nothing and no box term, the fine objective is the priors:
    the road prior turns cars heading 15 deg off the road back towards it (front or back
    alike), and without it their azimuths do not move towards the road."""
    camera, model, truth, dets, _ = synthetic_scene
    start = select_particles(lift_table(camera, dets), shared_plane=True, n_particles=1).take([0])
    off = np.deg2rad(15.0)
    start.azimuth[:] = np.array([np.pi / 2 + off, -np.pi / 2 - off, np.pi / 2 - off, -np.pi / 2 + off])
    ends = {}
    for weight in (0.0, InferenceOptions().road_prior):
        opts = InferenceOptions(iterations=10, samples=12, prune_after=0, box_weight=0.0, road_prior=weight,
                                polish_iterations=0)
        refined = refine_particles(camera, start, _Flat(), model, options=opts, rng=np.random.default_rng(1))
        assert np.all(np.diff(refined.history) >= -1e-12)
        ends[weight] = np.rad2deg(road_angle(refined.particles.azimuth[0]))
    # Measured: 4.1, 0.6, 0.0, 1.2 deg with the prior; 16, 22, 43, 55 deg without (a random walk).
    assert np.all(ends[InferenceOptions().road_prior] < 7.5), ends
    assert np.median(ends[0.0]) > 10.0, ends


def test_fine_road_prior_leaves_cars_the_coarse_stage_put_across_the_road(synthetic_scene):
    """The fine road prior acts only on cars whose coarse start heads within
    ``ROAD_PRIOR_WIDTH`` of the road: with silent evidence, cars starting 60 deg off it
    follow exactly the search they follow without any prior, while the cars starting 15
    deg off are still turned onto the road. Ungated, the prior pulls the former too."""
    camera, model, truth, dets, _ = synthetic_scene
    start = select_particles(lift_table(camera, dets), shared_plane=True, n_particles=1).take([0])
    near, across = np.deg2rad(15.0), np.deg2rad(60.0)
    start.azimuth[:] = np.array([np.pi / 2 + near, -np.pi / 2 - across, np.pi / 2 - across, -np.pi / 2 + near])
    ends = {}
    for name, kw in (("none", dict(road_prior=0.0)), ("gated", {}), ("ungated", dict(road_prior_gated=False))):
        # The plane stays fixed: its samples are judged by the whole scene, through which
        # the prior on the other cars would reach these.
        opts = InferenceOptions(iterations=10, samples=12, prune_after=0, box_weight=0.0, polish_iterations=0,
                                plane_refinement=False, **kw)
        refined = refine_particles(camera, start, _Flat(), model, options=opts, rng=np.random.default_rng(1))
        ends[name] = np.rad2deg(road_angle(refined.particles.azimuth[0]))
    assert_close(ends["gated"][[1, 2]], ends["none"][[1, 2]], atol=1e-9)
    assert np.all(ends["gated"][[0, 3]] < 7.5), ends
    # Measured: the cars across end 68 and 51 deg off the road with the gate (as without a
    # prior), 0.6 and 0.3 deg ungated; the cars near it 0.1 and 0.0 deg.
    assert np.min(ends["ungated"][[1, 2]]) < np.min(ends["none"][[1, 2]]) - 10.0, ends


def test_fine_search_keeps_each_car_within_its_viewpoint_window(synthetic_scene):
    """Cars starting 60 deg off the road under the ungated road prior, with silent
    evidence: the prior turns them onto the road, except that the viewpoint window keeps
    each car's observation angle within 45 deg of its pre-detection's viewpoint (here
    its start); a car of unknown viewpoint (NaN) stays free."""
    camera, model, truth, dets, _ = synthetic_scene
    start = select_particles(lift_table(camera, dets), shared_plane=True, n_particles=1).take([0])
    across = np.deg2rad(60.0)
    start.azimuth[:] = np.array([np.pi / 2 + across, -np.pi / 2 - across, np.pi / 2 - across, -np.pi / 2 + across])
    viewpoint = alpha_from_rotation_y(start.azimuth[0], start.x[0], start.z[0])
    alpha = viewpoint.copy()
    alpha[-1] = np.nan
    ends = {}
    for window in (0.0, 45.0):
        opts = InferenceOptions(iterations=10, samples=12, prune_after=0, box_weight=0.0, polish_iterations=0,
                                plane_refinement=False, road_prior_gated=False, viewpoint_window_deg=window)
        refined = refine_particles(camera, start, _Flat(), model, options=opts, rng=np.random.default_rng(1),
                                   alpha=alpha)
        p = refined.particles
        ends[window] = np.rad2deg(angle_difference(alpha_from_rotation_y(p.azimuth[0], p.x[0], p.z[0]), viewpoint))
    # Measured: 58-65 deg without the window; 45 deg with it (at its edge), 65 deg for the
    # car of unknown viewpoint.
    assert np.all(ends[45.0][:3] <= 45.0 + 1e-6), ends
    assert np.all(ends[0.0][:3] > 50.0), ends
    assert ends[45.0][3] > 50.0, ends  # unknown viewpoint: no window
    with pytest.raises(ShapeError):
        refine_particles(camera, start, _Flat(), model, options=opts, alpha=alpha[:-1])


@pytest.mark.parametrize("plane", [False, True])
def test_spread_grows_on_flat_and_shrinks_at_a_peak(synthetic_scene, plane):
    """The defining property of smoothing-based optimisation: the objective never
    decreases, and the sampling spread widens where the objective is flat and narrows
    around a distinct peak (here: starting at the true pose with perfect evidence)."""
    camera, model, truth, dets, evidence = synthetic_scene
    particles = select_particles(lift_table(camera, dets), shared_plane=True, n_particles=1)
    start = particles.take([0])
    start.x[:], start.z[:], start.azimuth[:] = truth["x"], truth["z"], truth["azimuth"]
    start.pitch[:], start.roll[:] = np.deg2rad(0.7), np.deg2rad(-0.3)
    # (no road prior: it would tilt the flat objective along the azimuth)
    opts = InferenceOptions(iterations=12, samples=12, prune_after=0, plane_refinement=plane, sigma_shape=1e-6,
                            n_shape=5, road_prior=0.0)
    # (more iterations on the flat objective: each update estimates the spread from 12
    # samples, so it grows by 1.3 only on average)
    flat = refine_particles(camera, start, _Flat(), model, options=dataclasses.replace(opts, iterations=30),
                            rng=np.random.default_rng(0))
    assert np.all(np.diff(flat.history) >= -1e-12)
    sigma0 = np.array([np.deg2rad(opts.sigma_bearing_deg), opts.sigma_range_frac, np.deg2rad(opts.sigma_azimuth_deg)])
    # (a spread estimated from 12 samples fluctuates: compare medians over the cars)
    assert np.median(flat.spread[..., :3] / sigma0) > 2.0
    peak = refine_particles(camera, start, evidence, model, options=opts, rng=np.random.default_rng(0))
    assert np.all(np.diff(peak.history) >= -1e-12)
    assert np.median(peak.spread[..., :2] / sigma0[:2]) < 1.0
    if plane:
        plane0 = np.deg2rad([opts.sigma_pitch_deg, opts.sigma_roll_deg])
        assert np.median(flat.plane_spread / plane0) > 2.0
        assert np.all(peak.plane_spread[0, 0] < plane0)


def test_plane_refinement_and_box_term_recover_a_tilted_plane(synthetic_scene):
    """Started on the coarse grid, the sampled plane moves towards the true (0.7, -0.3)
    deg plane, objects following along their rays; the objective never decreases."""
    from wirescene.lift import project_boxes

    camera, model, truth, dets, evidence = synthetic_scene
    # boxes in KITTI's convention: the projected 3D box of each true wireframe
    b = instantiate_wireframes(camera, model, pitch=np.full(4, np.deg2rad(0.7)), roll=np.full(4, np.deg2rad(-0.3)),
                               height=1.65, **truth)
    boxes, _ = project_boxes(camera, *b.extent, b.location, b.R)
    dets = Detections(boxes, 1.0, dets.alpha)
    # The boxes-only start (no road prior, whose start here is already within 0.37 m).
    lifted = lift_table(camera, dets, options=LiftingOptions(road_prior=0.0))
    particles = select_particles(lifted, shared_plane=True, n_particles=10)
    opts = InferenceOptions(iterations=15, plane_refinement=True, box_weight=100.0)
    refined = refine_particles(camera, particles, evidence, model, options=opts, rng=np.random.default_rng(0),
                               boxes=dets.boxes)
    assert np.all(np.diff(refined.history) >= -1e-9)
    best = refined.best_scene()
    p = refined.particles
    assert np.all(p.pitch[best] == p.pitch[best, 0])  # one plane per particle with +gp
    assert abs(np.rad2deg(p.pitch[best, 0]) - 0.7) < 0.3
    fine_err = np.median(np.hypot(p.x[best] - truth["x"], p.z[best] - truth["z"]))
    coarse_err = np.median(np.hypot(particles.x[0] - truth["x"], particles.z[0] - truth["z"]))
    assert fine_err < min(coarse_err, 1.0)


def test_box_cost_is_the_lifting_cost_in_kitti_convention(synthetic_scene):
    """The fine stage's box term of a mean-size box equals the coarse lifting cost."""
    from wirescene.core.boxes import MEAN_CAR_DIMS, box_extent_object
    from wirescene.core.groundplane import object_pose
    from wirescene.infer.inference import box_cost
    from wirescene.lift import solve_positions

    camera, model, truth, dets, evidence = synthetic_scene
    dims = np.broadcast_to(MEAN_CAR_DIMS, (len(dets), 3))
    x, z, az, cost = solve_positions(camera, dets.boxes, dets.alpha, 0.0, 0.0, dims)
    loc, R = object_pose(x, z, az, 0.0, 0.0)
    assert_close(box_cost(camera, box_extent_object(dims), loc, R, dets.boxes), cost, atol=1e-9)



def test_size_prior_is_the_negative_log_density_of_kitti_car_sizes(synthetic_scene):
    """size_cost: 0 at KITTI's mean car, half the squared deviation in standard
    deviations per dimension; the objective's penalty grows by size_prior times the
    size_cost of each hypothesis' wireframe box, so a much shortened car costs more."""
    from wirescene.core.boxes import KITTI_CAR_SIZE
    from wirescene.infer.inference import _geometry, _terms, _to_viewing, size_cost

    (l, w, h), (sl, _, sh) = KITTI_CAR_SIZE["mean"], KITTI_CAR_SIZE["std"]
    lo = np.array([[-l / 2, -h, -w / 2], [-l / 2 - sl, -h - 2 * sh, -w / 2]])
    hi = np.array([[l / 2, 0.0, w / 2], [l / 2, 0.0, w / 2]])
    assert_close(size_cost(lo, hi), [0.0, 0.5 * (1.0 + 4.0)], atol=1e-12)

    camera, model, truth, dets, evidence = synthetic_scene
    particles = select_particles(lift_table(camera, dets), shared_plane=False, n_particles=1)
    theta = np.zeros((1, len(dets), 2, 3 + 5))
    theta[..., :3] = np.stack(_to_viewing(particles.x, particles.z, particles.azimuth), -1)[:, :, None]
    theta[:, :, 1, 3] = 2.0  # first shape mode, 2 standard deviations: about 0.8 m shorter
    plain = _terms(camera, model, evidence, particles, theta, 5)
    priored = _terms(camera, model, evidence, particles, theta, 5, size_prior=2.0)
    added = priored.penalty - plain.penalty
    batch = _geometry(camera, model, (particles.pitch, particles.roll), particles.height, theta, 5)
    lo, hi = batch.extent
    # the extent kept at placement is the placed wireframe's, turned back into the object frame
    X = np.matmul(batch.vertices - batch.location[..., None, :], batch.R)
    assert_close(lo, X.min(axis=-2), atol=1e-9)
    assert_close(hi, X.max(axis=-2), atol=1e-9)
    assert_close(added, 2.0 * size_cost(lo, hi), atol=1e-6, rtol=1e-2)
    assert np.all(added[..., 1] > added[..., 0] + 1.0)


def test_oracle_evidence_peaks_at_the_matched_true_vertices():
    """Oracle evidence: the detectors' scale at the true visible vertices of the ground
    truth car a detection overlaps, falling off over ORACLE_SIGMA of the car length, and
    the floor for occluded vertices and for a detection that overlaps no car."""
    from wirescene.infer.evidence import ORACLE_FLOOR, ORACLE_PEAK, ORACLE_SIGMA, oracle_evidence
    from wirescene.io.wireframes import WireframeGT

    rng = np.random.default_rng(0)
    uv = rng.uniform(100, 300, (2, 36, 2))
    visible = np.ones((2, 36), bool)
    visible[1, :5] = False
    gt = WireframeGT(vertices_2d=list(uv), visible=list(visible), self_occluded=[np.zeros(36, bool)] * 2,
                     occluded_parts=[0, 5], ground_plane={})
    gt_boxes = np.array([[100, 100, 300, 300], [500, 100, 700, 300]], float)
    dets = Detections(np.array([[510, 105, 700, 300], [0, 0, 50, 50]], float), 1.0, np.zeros(2))
    ev = oracle_evidence(dets, gt_boxes, gt)
    scale = np.full((2,), 200.0)
    at_truth = ev.log_ratio(np.stack([uv[1], uv[1]]), np.array([0, 1]), scale)
    assert_close(at_truth[0, 5:], ORACLE_PEAK)  # detection 0 is car 1: its visible vertices
    assert_close(at_truth[0, :5], ORACLE_FLOOR)  # its occluded ones carry no evidence
    assert_close(at_truth[1], ORACLE_FLOOR)  # detection 1 overlaps no car
    shifted = ev.log_ratio(uv[1][None] + [ORACLE_SIGMA * 200.0, 0.0], np.array([0]), scale[:1])
    assert_close(shifted[0, 5:], ORACLE_FLOOR + (ORACLE_PEAK - ORACLE_FLOOR) * np.exp(-0.5))


def _search(synthetic_scene, shared, n_particles, pitch_deg=None, **opts):
    """A fine objective and the search state of Algorithm 1 at its coarse start (on
    planes of pitch ``pitch_deg`` instead of the coarse ones if given)."""
    from wirescene.infer.inference import FineObjective, SearchState

    camera, model, truth, dets, evidence = synthetic_scene
    particles = select_particles(lift_table(camera, dets), shared_plane=shared, n_particles=n_particles)
    if pitch_deg is not None:
        particles.pitch[:] = np.deg2rad(pitch_deg)
    objective = FineObjective.create(camera, model, evidence, InferenceOptions(**opts), n_objects=len(dets),
                                     boxes=dets.boxes)
    return objective, SearchState.start(objective, particles)


@pytest.mark.parametrize("shared", [True, False])
def test_prune_keeps_the_best_rows_of_every_array(synthetic_scene, shared):
    """Pruning keeps the best scenes (coupled objects) or each object's own best
    particles (independent ones), and every per-particle array follows the same rows."""
    objective, state = _search(synthetic_scene, shared, 5)
    state.score = np.array([[0.0, 4.0, 1.0, 0.0], [3.0, 0.0, 0.0, 2.0], [1.0, 1.0, 5.0, 1.0],
                            [9.0, -9.0, 0.0, 0.0], [2.0, 2.0, 2.0, 2.0]])
    before = dataclasses.replace(state)
    state.prune(objective, 2)
    # scene sums 5, 5, 8, 0, 8 (stable order among ties); per object the two best.
    rows = np.array([[2, 2, 2, 2], [4, 4, 4, 4]]) if shared else np.array([[3, 0, 2, 1], [1, 4, 4, 4]])
    cols = np.arange(4)
    for name in ("theta", "sigma", "sigma0", "score", "plane", "plane_sigma", "plane_sigma0"):
        assert_close(getattr(state, name), getattr(before, name)[rows, cols], atol=0, msg=name)
    assert_close(state.current.uv, before.current.uv[rows, cols], atol=0)
    assert_close(state.particles.azimuth, before.particles.azimuth[rows, cols], atol=0)
    assert state.mask is None and state.gamma is None


def test_plane_step_moves_all_cars_of_a_particle_by_one_shared_plane(synthetic_scene):
    """The plane step samples one plane per particle with +gp and moves every car along
    its viewing ray onto it (the bottom centre stays on its pixel, observation angle and
    shape unchanged); the kept geometry is that of the new state and no particle's scene
    objective decreases. (Started 1.7 deg below the true plane, so that samples win.)"""
    from wirescene.core.groundplane import point_on_plane
    from wirescene.infer.inference import _from_viewing

    objective, state = _search(synthetic_scene, True, 3, pitch_deg=-1.0, sigma_pitch_deg=0.5, sigma_roll_deg=0.5)
    camera = objective.camera
    before = dataclasses.replace(state, theta=state.theta.copy(), plane=state.plane.copy())

    def foot(theta, plane):
        x, z, _ = _from_viewing(theta)
        return camera.project(point_on_plane(x, z, plane[..., 0], plane[..., 1], state.particles.height))

    state.plane_step(objective, np.random.default_rng(0), 12)
    assert_close(state.plane, np.broadcast_to(state.plane[:, :1], state.plane.shape), atol=0)
    assert_close(state.plane_sigma, np.broadcast_to(state.plane_sigma[:, :1], state.plane_sigma.shape), atol=0)
    assert np.all(state.plane[..., 0] > before.plane[..., 0])  # measured: -1 -> -0.35, -0.33, -0.13 deg
    assert_close(foot(state.theta, state.plane), foot(before.theta, before.plane), atol=1e-6)
    assert_close(state.theta[..., 2:], before.theta[..., 2:], atol=0)
    fresh = objective.value(objective.terms(state.particles, state.theta[:, :, None], state.plane), None, None)
    assert_close(state.score, fresh[..., 0], atol=1e-9)
    assert np.all(objective.scene(state.score) >= objective.scene(before.score) - 1e-12)


def test_pose_step_samples_only_its_block_and_never_loses_an_object(synthetic_scene):
    """A pose step moves bearing, range and observation angle alone; each object's
    objective never decreases (its current value is among the candidates)."""
    objective, state = _search(synthetic_scene, False, 4)
    before = dataclasses.replace(state, theta=state.theta.copy(), sigma=state.sigma.copy())
    state.pose_step(objective, np.random.default_rng(0), np.arange(3), 12)
    assert np.all(state.score >= before.score)
    assert np.any(state.theta[..., :3] != before.theta[..., :3])
    assert_close(state.theta[..., 3:], before.theta[..., 3:], atol=0)
    assert_close(state.sigma[..., 3:], before.sigma[..., 3:], atol=0)  # only the block's spread changes


def test_oracle_evidence_checks_its_visibility_against_its_vertices():
    from wirescene.infer.likelihood import GaussianVertexEvidence

    uv = np.zeros((2, 36, 2))
    GaussianVertexEvidence(uv, np.ones((2, 36), bool))  # one flag a vertex of each car
    with pytest.raises(ShapeError, match="visible must have shape"):
        GaussianVertexEvidence(uv, np.ones(36, bool))  # one car's flags would stand for every car's vertices
