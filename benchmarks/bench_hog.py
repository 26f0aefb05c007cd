"""The pre-detection's HOG against another revision's, side by side in one run.

``--against FILE`` is a ``wirescene/predetect/hog.py`` of another revision, e.g.
``git show REV:src/wirescene/predetect/hog.py > OLD_HOG.py``. Both modules' ``hog_cells``,
``crop_features``, ``crops_features`` (a revision without it: its ``crop_features`` one window
at a time) and ``feature_pyramid`` are swapped into the detector in turn, and the
shipped bank's ``detect_cars`` runs on the same frames, alternating between them, on one
core (BLAS threads limited to 1; CPU time of this process). It prints whether the two give
identical detections (or how far apart they are), the CPU seconds per frame of each (best of ``--repeat`` passes) and
their ratio, the same for ``crops_features`` on 256 windows of the refinement's grid, and for
``hog_cells`` alone on a 112 x 80 crop (the refinement's and the verifier's windows) and on a
2x-upsampled frame (the pyramid's largest level).

    python benchmarks/bench_hog.py --root ../shared/data/kitti --against OLD_HOG.py [--frames 5]
"""

from __future__ import annotations

import argparse
import importlib.util
import time


def agreement(a, b) -> str:
    """"identical", or the largest difference of two arrays of one shape."""
    import numpy as np

    if np.array_equal(a, b):
        return "identical"
    return f"within {np.abs(np.asarray(a, float) - np.asarray(b, float)).max():.2g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", required=True, help="labelled KITTI root (e.g. ../shared/data/kitti)")
    ap.add_argument("--against", required=True, help="hog.py of another revision")
    ap.add_argument("--frames", type=int, default=5, help="the first N frames of the root")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()

    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    import numpy as np

    import wirescene.predetect.bank as bank_module
    import wirescene.predetect.hog as hog
    import wirescene.predetect.refine as refine
    from wirescene.io.kitti import KittiDataset

    spec = importlib.util.spec_from_file_location("other_hog", args.against)
    if spec is None:
        raise SystemExit(f"{args.against}: not a Python file")
    other = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(other)
    names = ("hog_cells", "crop_features", "crops_features", "feature_pyramid")

    def crop_by_crop(crop_features):  # a revision without crops_features: one crop at a time, as it did
        def crops_features(gray, boxes, th, tw):
            b = np.asarray(boxes, float).reshape(-1, 4)
            return np.stack([crop_features(gray, box, th, tw) for box in b]) if len(b) else \
                np.zeros((0, th, tw, hog.N_FEAT), np.float32)
        return crops_features

    versions = {v: {n: getattr(m, n, None) for n in names} for v, m in (("this", hog), ("other", other))}
    for v in versions.values():
        v["crops_features"] = v["crops_features"] or crop_by_crop(v["crop_features"])

    def use(version: str) -> None:
        for module in (hog, bank_module, refine):
            for n in names:
                if hasattr(module, n):
                    setattr(module, n, versions[version][n])

    def cpu(fn, repeat: int) -> tuple[float, object]:
        best, out = np.inf, None
        for _ in range(repeat):
            t0 = time.process_time()
            out = fn()
            best = min(best, time.process_time() - t0)
        return best, out

    ds = KittiDataset(args.root)
    ids = ds.frame_ids()[: args.frames]
    frames = [(ds.image(f), ds.camera(f)) for f in ids]
    bank = bank_module.load_default_bank()
    seconds = {v: np.inf for v in versions}
    dets = {}
    for _ in range(args.repeat):  # alternating, so that load on the machine falls on both alike
        for v in versions:
            use(v)
            t, dets[v] = cpu(lambda: [bank_module.detect_cars(im, bank=bank, camera=cam, return_all=True)
                                      for im, cam in frames], 1)
            seconds[v] = min(seconds[v], t / len(frames))
    use("this")
    pairs = list(zip(dets["this"], dets["other"]))
    if not all(len(a.boxes) == len(b.boxes) and np.array_equal(a.alpha, b.alpha) for a, b in pairs):
        same = "different detections"
    else:
        same = agreement(np.concatenate([a.boxes for a, _ in pairs]), np.concatenate([b.boxes for _, b in pairs]))
        same += ", scores " + agreement(np.concatenate([a.scores for a, _ in pairs]),
                                        np.concatenate([b.scores for _, b in pairs]))
    n = sum(len(d.boxes) for d in dets["this"])
    print(f"detect_cars on {len(frames)} frames ({n} detections): boxes {same}; CPU s/frame "
          f"this {seconds['this']:.2f}, other {seconds['other']:.2f}, other / this {seconds['other'] / seconds['this']:.2f}x")

    gray = hog.to_gray(frames[0][0])
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, gray.shape[1] - 120, 256), rng.uniform(100, gray.shape[0] - 60, 256)
    boxes = np.column_stack([x, y, x + rng.uniform(20, 120, 256), y + rng.uniform(15, 60, 256)])
    t = {v: cpu(lambda f=versions[v]["crops_features"]: f(gray, boxes, 8, 12), args.repeat + 1)[0] for v in versions}
    equal = agreement(versions["this"]["crops_features"](gray, boxes, 8, 12),
                      versions["other"]["crops_features"](gray, boxes, 8, 12))
    print(f"crops_features, 256 windows of 8 x 12 cells: {equal}; this {t['this'] * 1e3:.1f} ms, "
          f"other {t['other'] * 1e3:.1f} ms, other / this {t['other'] / t['this']:.2f}x")
    crop = np.ascontiguousarray(gray[100:212, 300:380])
    big = hog.resize(gray, 2 * gray.shape[1], 2 * gray.shape[0])
    for name, image, reps in (("112 x 80 crop", crop, 2000), (f"{big.shape[1]} x {big.shape[0]} level", big, 10)):
        t = {v: cpu(lambda f=versions[v]["hog_cells"], x=image, k=reps: [f(x) for _ in range(k)], args.repeat + 1)[0] / reps
             for v in versions}
        equal = agreement(versions["this"]["hog_cells"](image), versions["other"]["hog_cells"](image))
        print(f"hog_cells, {name}: {equal}; this {t['this'] * 1e3:.3f} ms, other {t['other'] * 1e3:.3f} ms, "
              f"other / this {t['other'] / t['this']:.2f}x")


if __name__ == "__main__":
    main()
