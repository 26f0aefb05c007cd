"""Which rule says a synthetic car's landmark is hidden by its own body, measured.

The synthetic scenes label a landmark self-occluded by casting a ray to it pushed 3 cm
away from the car's centre (``synth.generate.VERTEX_PUSH``, a surface more than 2 cm
before it blocks); the CAD renderings of :func:`wirescene.render.project_landmarks` cast
to the landmark itself. The real frames' part labels and the fit itself judge the same
thing on the wireframe's own hull (:func:`wirescene.infer.occlusion.self_occlusion`).
This script scores, on the landmarks inside the image of every labelled car of ``--scenes``
synthetic scenes, each rule against the hull and against the synthetic labels:

    python benchmarks/bench_landmark_visibility.py [--scenes 30] [--seed 11]
"""

from __future__ import annotations

import argparse

import numpy as np

from wirescene.core.wireframe import FACES
from wirescene.infer.occlusion import self_occlusion
from wirescene.render import project_landmarks
from wirescene.synth.generate import generate_scene, load_car_library, resized

TOLERANCES = (0.02, 0.05, 0.10)


def own_hidden(scene) -> dict:
    """``{rule: (K,) bool}`` over the landmarks in the image of the scene's labelled cars:
    hidden by the car's own body by the synthetic label, the exact ray to the landmark at
    each tolerance, and the wireframe's hull."""
    library = load_car_library()
    out = {"label": [], "hull": [], **{f"ray {t:.2f} m": [] for t in TOLERANCES}}
    for car in scene.wireframes["cars"]:
        keep = np.array([r != "truncated" for r in car["visibility"]])
        m = resized(library[car["cad_model"]], car["dims_hwl"])
        loc, R = np.array(car["location"]), np.array(car["R"])
        out["label"].append(np.array([r == "self" for r in car["visibility"]])[keep])
        X = np.array(car["vertices_3d"])
        out["hull"].append(self_occlusion(X, FACES, scene.camera.center)[keep])
        for t in TOLERANCES:
            _, _, vis = project_landmarks(m.landmarks, m.vertices, m.faces, scene.camera, loc, R, tolerance=t)
            out[f"ray {t:.2f} m"].append(~vis[keep])
    return {k: np.concatenate(v) if v else np.zeros(0, bool) for k, v in out.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args()
    rules: dict[str, list] = {}
    for k in range(args.scenes):
        for rule, hidden in own_hidden(generate_scene(args.seed, k)).items():
            rules.setdefault(rule, []).append(hidden)
    hidden = {rule: np.concatenate(v) for rule, v in rules.items()}
    n = len(hidden["label"])
    print(f"{args.scenes} synthetic scenes (seed {args.seed}), {n} landmarks of labelled cars inside the image\n")
    print(f"{'rule':<18}{'self-hidden':>12}{'agrees with hull':>18}{'agrees with label':>19}"
          f"{'label/rule differ: hull sides with label':>42}")
    for rule, h in hidden.items():
        differ = h != hidden["label"]
        sides = (hidden["hull"][differ] == hidden["label"][differ]).sum()
        cell = "-" if rule in ("label", "hull") else f"{sides} of {differ.sum()}"
        print(f"{rule:<18}{h.sum():>12}{np.mean(h == hidden['hull']):>18.1%}{np.mean(h == hidden['label']):>19.1%}"
              f"{cell:>42}")


if __name__ == "__main__":
    main()
