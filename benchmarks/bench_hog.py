"""The pre-detection's HOG against another revision's, side by side in one run.

``--against FILE`` is a ``wirescene/predetect/hog.py`` of another revision, e.g.
``git show REV:src/wirescene/predetect/hog.py > OLD_HOG.py``. Both modules' ``hog_cells``,
``crop_features`` and ``feature_pyramid`` are swapped into the detector in turn, and the
shipped bank's ``detect_cars`` runs on the same frames, alternating between them, on one
core (BLAS threads limited to 1; CPU time of this process). It prints whether the two give
identical detections, the CPU seconds per frame of each (best of ``--repeat`` passes) and
their ratio, and the same for ``hog_cells`` alone on a 112 x 80 crop (the refinement's and
the verifier's windows) and on a 2x-upsampled frame (the pyramid's largest level).

    python benchmarks/bench_hog.py --root ../shared/data/kitti --against OLD_HOG.py [--frames 5]
"""

from __future__ import annotations

import argparse
import importlib.util
import time


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
    names = ("hog_cells", "crop_features", "feature_pyramid")
    versions = {"this": {n: getattr(hog, n) for n in names}, "other": {n: getattr(other, n) for n in names}}

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
    same = all(np.array_equal(a.boxes, b.boxes) and np.array_equal(a.scores, b.scores)
               and np.array_equal(a.alpha, b.alpha) for a, b in zip(dets["this"], dets["other"]))
    n = sum(len(d.boxes) for d in dets["this"])
    print(f"detect_cars on {len(frames)} frames ({n} detections): identical {same}; CPU s/frame "
          f"this {seconds['this']:.2f}, other {seconds['other']:.2f}, other / this {seconds['other'] / seconds['this']:.2f}x")

    gray = hog.to_gray(frames[0][0])
    crop = np.ascontiguousarray(gray[100:212, 300:380])
    big = hog.resize(gray, 2 * gray.shape[1], 2 * gray.shape[0])
    for name, image, reps in (("112 x 80 crop", crop, 2000), (f"{big.shape[1]} x {big.shape[0]} level", big, 10)):
        t = {v: cpu(lambda f=versions[v]["hog_cells"], x=image, k=reps: [f(x) for _ in range(k)], args.repeat + 1)[0] / reps
             for v in versions}
        equal = np.array_equal(versions["this"]["hog_cells"](image), versions["other"]["hog_cells"](image))
        print(f"hog_cells, {name}: identical {equal}; this {t['this'] * 1e3:.3f} ms, other {t['other'] * 1e3:.3f} ms, "
              f"other / this {t['other'] / t['this']:.2f}x")


if __name__ == "__main__":
    main()
