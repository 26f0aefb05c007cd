"""Click commands for the CAD exemplars and shape-model training, registered by the
main CLI: the group ``cad`` (``list``, ``show``) and the command ``shape`` (meant as
``wirescene train shape``)."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from wirescene.cli.options import NON_NEGATIVE, NonEmptyPath, check_output_file, check_picture_file
from wirescene.core.errors import InputError

__all__ = ["cad", "shape", "draw_car"]

#: Most size-augmented copies per exemplar `train shape` makes: 14 exemplars x 10,000 copies of 108
#: numbers are 120 MB for the PCA; 10^7 would be 120 GB.
MAX_AUGMENT = 10_000


def _cad_dir(value) -> Path:
    """``--cad-dir``, or the default one (checked where its files are listed, ``list_cad_files``)."""
    from wirescene.cad.mesh import default_cad_dir

    return Path(value) if value else default_cad_dir()


def _find(cad_dir: Path, name: str) -> Path:
    from wirescene.cad.mesh import list_cad_files

    files = list_cad_files(cad_dir)
    for f in files:
        if f.stem == name or f.name == name:
            return f
    raise InputError(f"no CAD model named {name!r} (have: {', '.join(f.stem for f in files)})", path=cad_dir)


def _name_landmarks(fig, ax, points, names, *, fontsize: float = 7) -> None:
    """Write ``names`` by ``points`` (data units of ``ax``), each up and right of its point
    where there is room, else moved clear of the other names and dots with a line to its
    point (:func:`wirescene.io.pictures.place_labels`, in the figure's pixels as laid out)."""
    from wirescene.io.pictures import place_labels, text_size

    if not len(names):
        return
    ax.apply_aspect()  # the equal aspect's final scale, before the points are measured
    per_point = fig.dpi / 72
    xy = ax.transData.transform(points)
    x, y = xy[:, 0], fig.bbox.height - xy[:, 1]  # y down, as place_labels measures
    gap = 2 * per_point
    dots = [(u - gap, v - gap, u + gap, v + gap) for u, v in zip(x, y)]
    sizes = [text_size(n, fontsize, per_point, 0) for n in names]
    corners = place_labels([(u + gap, v - gap, u + gap, v - gap) for u, v in zip(x, y)], sizes, fig.bbox.width,
                           fig.bbox.height, reserved=dots)
    for name, point, u, v, (cx, cy), (_, th) in zip(names, points, x, y, corners, sizes):
        dx, dy = (cx - u) / per_point, (v - cy) / per_point  # offset of the name's top-left corner, points, y up
        moved = np.hypot(dx - 2, dy - 2 - th / per_point) > 6
        ax.annotate(name, point, xytext=(dx, dy),
                    textcoords="offset points", fontsize=fontsize, ha="left", va="top",
                    arrowprops=dict(arrowstyle="-", lw=0.4, color="0.4") if moved else None)


def draw_car(vertices, faces, X, *, title: str = "", out=None):
    """Three orthographic views (side, top, front) of a mesh with the 36 landmarks, their
    names and the wireframe edges, and a key to the colours (landmarks on the near side of
    a view red and named, on the far side open orange dots), the axes in metres of the object frame
    (x forward, y down, z to the car's left). Returns the matplotlib figure
    (:func:`wirescene.io.pictures.new_figure`)."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.lines import Line2D

    from wirescene.core.wireframe import EDGES, N_PER_SIDE, VERTEX_NAMES
    from wirescene.io.pictures import new_figure

    fig = new_figure(figsize=(14, 16))
    named = []  # (axes, points, names): written once the layout is fixed, clear of each other
    axes = fig.subplots(3, 1, gridspec_kw={"height_ratios": [1.0, 1.4, 1.0]})
    # (title, horizontal axis, vertical axis, sign of vertical, depth axis, axis labels) in object coordinates; the
    # front view's +z (the car's left) on the right, as seen standing in front of the car
    forward, left, height = "x: forward (m)", "z: to the car's left (m)", "height above the ground (m)"
    # forward to the right in the side view is the car seen from its right: the left side's landmarks seen through it
    views = (("side (seen from the right, forward to the right; the left side's landmarks red)", 0, 1, -1.0, 2, forward,
              height), ("top (seen from above)", 0, 2, 1.0, 1, forward, left),
             ("front (looking at the car's front; names on its left side)", 2, 1, -1.0, 0, left, height))
    for ax, (label, a, b, sb, depth_axis, xlabel, ylabel) in zip(axes, views):
        tri = np.stack([vertices[faces][..., a], sb * vertices[faces][..., b]], axis=-1)
        ax.add_collection(PolyCollection(tri, facecolor="none", edgecolor="0.7", linewidths=0.2))
        P = np.stack([X[:, a], sb * X[:, b]], axis=1)
        near = X[:, depth_axis] >= 0 if depth_axis == 2 else np.ones(len(X), bool)
        if depth_axis == 0:
            near = X[:, 0] >= np.median(X[:, 0])
        ax.add_collection(LineCollection(P[EDGES], colors="tab:blue", linewidths=1.0))
        # the far side's dots open (not only orange): red and orange look alike to a red-green deficient reader
        ax.scatter(P[~near, 0], P[~near, 1], s=16, facecolors="white", edgecolors="tab:orange", linewidths=1.0,
                   zorder=3)
        ax.scatter(P[near, 0], P[near, 1], s=18, c="tab:red", zorder=4)
        # one side's names where both sides show (top, front): half the clutter
        shown = [i for i in range(len(X)) if near[i] and (depth_axis == 2 or i < N_PER_SIDE)]
        named.append((ax, P[shown], [VERTEX_NAMES[i].replace("_left", "").replace("_right", "") for i in shown]))
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(label, fontsize=9)
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    key = [Line2D([], [], ls="none", marker="o", ms=5, color="tab:red"), Line2D([], [], ls="none", marker="o", ms=4,
           color="tab:orange", mfc="white"), Line2D([], [], color="tab:blue", lw=1.0), Line2D([], [], color="0.7", lw=0.6)]
    fig.legend(key, ["landmark, near side (named)", "landmark, far side", "wireframe edge", "mesh"], loc="lower center",
               ncol=4, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.02, 1, 1))  # room for the key below the views
    for ax, points, names in named:
        _name_landmarks(fig, ax, points, names)
    if out is not None:
        from wirescene.io.pictures import save_figure

        save_figure(fig, out, dpi=90)
    return fig


@click.group("cad")
def cad():
    """CAD car exemplars: list them, show their annotated wireframes."""


@cad.command("list")
@click.option("--cad-dir", type=NonEmptyPath(file_okay=False), default=None,
              help="Mesh directory (default: $WIRESCENE_CAD_DIR or ../shared/data/cad/torcs).")
def list_cmd(cad_dir):
    """Names, dimensions (l, w, h) and road / non-road decision with its reason."""
    from wirescene.cad.mesh import list_cad_files, load_car, road_car_check

    for path in list_cad_files(_cad_dir(cad_dir)):
        car = load_car(path)
        is_road, reason = road_car_check(car)
        click.echo(f"{car.name:16s} {'road    ' if is_road else 'NON-ROAD'} {reason}")


@cad.command("show")
@click.argument("name")
@click.option("--out", type=NonEmptyPath(dir_okay=False), default=None,
              help="Picture to write, in the format its suffix names (.png, .pdf, .svg; default: NAME.png).")
@click.option("--cad-dir", type=NonEmptyPath(file_okay=False), default=None,
              help="Mesh directory (default: $WIRESCENE_CAD_DIR or ../shared/data/cad/torcs).")
def show_cmd(name, out, cad_dir):
    """Picture of one car: three orthographic views with the 36 annotated vertices."""
    from wirescene.cad.landmarks import annotate
    from wirescene.cad.mesh import load_car, naming_the_file, road_car_check

    check_picture_file(Path(out or f"{name}.png"), "--out")  # the default is the car's name in the working directory
    path = _find(_cad_dir(cad_dir), name)
    car = load_car(path)
    is_road, reason = road_car_check(car)
    with naming_the_file(path):
        X = annotate(car.vertices, car.faces, name=car.name)
    out = out or f"{car.name}.png"
    draw_car(car.vertices, car.faces, X, title=f"{car.name}: {reason}", out=out)
    click.echo(out)


@click.command("shape")
@click.option("--cad-dir", type=NonEmptyPath(file_okay=False), default=None,
              help="Mesh directory (default: $WIRESCENE_CAD_DIR or ../shared/data/cad/torcs).")
@click.option("--out", type=NonEmptyPath(dir_okay=False, path_type=Path), required=True,
              help="Shape model .npz to write (the shipped one is src/wirescene/data/shape_model.npz); "
                   "cad_landmarks.json and cad_meshes.npz are written next to it.")
@click.option("--seed", type=NON_NEGATIVE, default=0, show_default=True, help="Seed of the size augmentation.")
@click.option("--augment", type=click.IntRange(min=0, max=MAX_AUGMENT), default=None,
              help=f"Size-augmented copies per exemplar (default 100; at most {MAX_AUGMENT:,}, the PCA holding them "
                   "all in memory).")
def shape(cad_dir, out, seed, augment):
    """Train the metric PCA wireframe shape model from CAD meshes."""
    from wirescene.cad.training import DEFAULT_AUGMENT, train_shape_model

    check_output_file(out, "--out")
    for beside in ("cad_landmarks.json", "cad_meshes.npz"):  # written next to --out, checked as it is
        check_output_file(out.parent / beside, "--out")
    model = train_shape_model(_cad_dir(cad_dir), out, seed=seed,
                              augment=DEFAULT_AUGMENT if augment is None else augment, progress=click.echo)
    ev = ", ".join(f"{v:.3f}" for v in model.explained_variance_ratio[:8])
    click.echo(f"{out}: {len(model.exemplar_names)} exemplars, {model.n_components} components; "
               f"explained variance {ev} ...")
