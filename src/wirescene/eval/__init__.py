"""Evaluation of scene estimates: the paper's protocol and the KITTI object benchmark
(:mod:`wirescene.eval.kitti_metrics`)."""
