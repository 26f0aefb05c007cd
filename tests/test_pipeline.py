import numpy as np

from conftest import KITTI_ROOT
from wirescene.datasets.kitti import KittiDataset
from wirescene.pipeline import evaluate_dataset
from wirescene.scene.fit import FitOptions
from wirescene.scene.inference import InferenceOptions
from wirescene.scene.lifting import LiftingOptions


def test_parallel_evaluation_equals_serial():
    ds = KittiDataset(KITTI_ROOT)
    opts = FitOptions(lifting=LiftingOptions(n_particles=6), inference=InferenceOptions(iterations=2, samples=4), seed=1)
    kw = dict(frames=["000002", "001545"], options=opts)
    serial = evaluate_dataset(ds, ["coarse+gp", "fg"], workers=1, **kw)
    parallel = evaluate_dataset(ds, ["coarse+gp", "fg"], workers=2, **kw)
    for v in serial:
        a = [r.loc_error for r in serial[v].records]
        b = [r.loc_error for r in parallel[v].records]
        assert len(a) == 7 and np.array_equal(a, b)
