"""KITTI label files for every image of a split, labelled or not (``wirescene predict``):
the file set the KITTI benchmark server expects, one ``FRAME.txt`` per image with a
score per car. Frames are fitted serially, in processes or on Dask, like ``eval``, and
an interrupted run resumes: ``OUT/.predict.json`` records the settings, and a frame
whose label file exists (written atomically, after the frame's other files) is not fitted
again under the same settings. Besides the label files, each frame's JSON (the cars' boxes
and ground plane, and of a fine variant their wireframes and visible vertices, as ``fit``
writes it) and its two pictures may be written to folders of their own, the label folder
staying a submission."""

from __future__ import annotations

import json
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Mapping

from wirescene.core.artefacts import format_tag
from wirescene.core.atomic import write_bytes, write_text
from wirescene.core.errors import ArgumentError, InputError
from wirescene.core.labels import CAR_TYPES
from wirescene.core.validate import output_dir_problem
from wirescene.core.version import __version__
from wirescene.eval.records import resumed_settings, settings_record
from wirescene.eval.runner import check_frames_boxes, check_images_read, fit_frames, notify_stderr, say_off_centre
from wirescene.eval.sources import DetectionSource, frame_seed
from wirescene.fitting.models import models_fingerprint, options_read
from wirescene.fitting.options import FitOptions
from wirescene.fitting.pipeline import fit_frame, needs_evidence
from wirescene.fitting.variants import DEFAULT_VARIANT, get_variant
from wirescene.io.kitti import KittiDataset, as_frame_ids
from wirescene.io.outputs import fit_output_paths, scene_json, scene_pictures

CONFIG_FILE = ".predict.json"
#: The folders :func:`predict_dataset` writes, by its arguments' names: how its refusals name them by default.
FOLDERS = ("out_dir", "json_dir", "pictures_dir")
#: How :func:`predict_dataset`'s refusals name its arguments by default (a command names its options).
ARGUMENT_NAMES = {**{name: name for name in FOLDERS}, "resume": "resume=True"}


@dataclass(frozen=True)
class _PredictJob:
    dataset: KittiDataset
    variant: str
    source: DetectionSource
    options: FitOptions
    json_dir: Path | None = None
    pictures_dir: Path | None = None

    def __call__(self, frame_id: str) -> tuple[str, str, dict[Path, bytes]]:
        """``(frame, label file's text, {path: bytes} of its other files)``: the files are written
        by the process that gathers the frames (a worker writes none)."""
        camera = self.dataset.camera(frame_id)
        detections = self.source.for_frame(self.dataset, frame_id, frame_seed(self.options.seed, frame_id),
                                           predetect=self.options.predetect, lifting=self.options.lifting)
        # the image where the fit or the pictures read it (check_images_read decodes these before the first fit)
        reads = self.pictures_dir is not None or needs_evidence(detections, [self.variant])
        image = self.dataset.image(frame_id) if reads else None
        fitted = fit_frame(camera, detections, [self.variant], image=image, options=self.options,
                           own=self.source.own)
        estimate = fitted.estimates[self.variant]
        files = {}
        if self.json_dir is not None:
            path = fit_output_paths(self.json_dir, frame_id)["json"]
            files[path] = scene_json(frame_id, estimate, fitted.detections).encode()
        if self.pictures_dir is not None:
            label_file = self.dataset.label_path(frame_id)  # a labelled split's cars drawn beside the estimate
            gt = self.dataset.labels(frame_id).of_type(*CAR_TYPES) if label_file.is_file() else None
            pictures = scene_pictures(frame_id, image=image, camera=camera, estimate=estimate,
                                      detections=fitted.detections, gt=gt)
            paths = fit_output_paths(self.pictures_dir, frame_id)
            files.update({paths[kind]: data for kind, data in pictures.items()})
        return frame_id, estimate.to_kitti(), files


def _config(dataset: KittiDataset, variant: str, source: DetectionSource, options: FitOptions,
            folders: dict[str, str] | None = None) -> dict:
    spec = source.spec if source.spec in ("gt", "bank") else str(Path(source.spec).resolve())
    # the trained files the fit reads, by path and content: another file it does not read changes nothing
    read = {"fine": get_variant(variant).fine, "own": source.own, "evidence": "parts"}
    config = {"format": format_tag("predict-config", 1), "wirescene": __version__,
              **dataset.record(), "variant": variant,
              "detections": {"spec": spec, "allow_missing": source.allow_missing, **source.floor_record()},
              "options": options_read(options, **read), "models": models_fingerprint(options, **read),
              **({"folders": folders} if folders else {})}  # none given: the record of a run begun before them
    return json.loads(json.dumps(config, default=str))


def _folder_problem(out: Path, folders: dict[str, Path | None], dataset: KittiDataset,
                    source: DetectionSource, names: Mapping[str, str]) -> None:
    """An :class:`InputError` naming ``out``, ``json_dir`` or ``pictures_dir`` (``folders``) where
    its files would spoil another folder's: the label folder (a submission holds the label files
    alone), or any folder the run reads, the images', the detections' (a frame's ``FRAME.json`` or
    ``FRAME.txt`` there takes the place of its detection file, or sits beside it as a second one),
    the split's own ``label_2`` / ``calib`` (the next run's ground truth, or calibrations).
    ``names``: how the message names each folder of :data:`FOLDERS` (the arguments' names, or the
    command's options)."""
    submission = f"{names['out_dir']}, the label folder: a submission holds the label files alone"
    replaces = "each frame's {} written there would replace its detection file or be a second one"
    # each folder the run reads, with what an output's files would do there (any other: nothing belongs there)
    inputs = [(dataset.image_dir, "the folder of the images",
               {"out_dir": "a submission holds the label files alone",
                "pictures_dir": "each picture written there would be a frame of the next run"}),
              (source.folder, "the detections' folder",
               {"out_dir": replaces.format("label file"), "json_dir": replaces.format("FRAME.json")}),
              (dataset.split_dir / "label_2", "the split's label folder",
               {"out_dir": "the next run would read the label files as the frames' ground truth"}),
              (dataset.split_dir / "calib", "the split's calibration folder",
               {"out_dir": "each FRAME.txt there is a frame's calibration"})]
    taken = [("json_dir", out, submission), ("pictures_dir", out, submission)]
    taken += [(name, folder, f"{what}: {why.get(name, 'a run writes nothing among what it reads')}")
              for name in FOLDERS for folder, what, why in inputs]
    folders = {"out_dir": out, **folders}
    for name, other, what in taken:
        folder = folders[name]
        if folder is not None and other is not None and folder.resolve() == Path(other).resolve():
            raise InputError(f"{names[name]} is {what}; give it a folder of its own", path=folder)


def _others_files(frame_ids: list[str], folders: dict[str, Path | None], names: Mapping[str, str],
                  resumed: dict | None = None) -> None:
    """An :class:`InputError` naming ``json_dir`` or ``pictures_dir`` (``folders``) where it
    already holds a file this run would write (another run's, not resumed: it would be written
    over, the folder a mix of two runs' frames); ``resumed``: the settings' record a run asked to
    resume found (``{}``: none), which is not this run's. ``names``: how the message names the
    label folder (:func:`_folder_problem`'s)."""
    kinds = {"json_dir": ("json",), "pictures_dir": ("overlay", "bev")}  # of fit_output_paths
    if resumed is None:
        advice = f"use {names['resume']} to continue that run"
    else:  # --resume given: the label folder's record is none, or another run's
        records = "other settings" if resumed else "no run"
        advice = f"{CONFIG_FILE} in {names['out_dir']} records {records}: resume that run"
    for name, folder in folders.items():
        if folder is None or not folder.is_dir():
            continue
        held = [p.name for f in frame_ids for kind, p in fit_output_paths(folder, f).items()
                if kind in kinds[name] and p.exists()]
        if held:
            raise InputError(f"already holds {len(held)} of the files this run writes (e.g. {held[0]}), another "
                             f"run's: {advice} or choose an empty directory", path=folder)


def predict_dataset(
    dataset: KittiDataset,
    out_dir,
    *,
    variant: str = DEFAULT_VARIANT,
    source: DetectionSource | None = None,
    options: FitOptions | None = None,
    frames: Iterable[str | int] | str | int | None = None,
    resume: bool = False,
    workers: int = 1,
    dask_client=None,
    progress: Callable[[Iterable], Iterable] = lambda it: it,
    notify: Callable[[str], None] | None = None,
    json_dir: str | Path | None = None,
    pictures_dir: str | Path | None = None,
    names: Mapping[str, str] | None = None,
) -> list[str]:
    """Write ``out_dir/FRAME.txt`` (KITTI labels with scores) for every image.

    Parameters
    ----------
    dataset : KittiDataset
        Any split; labels are not needed unless ``source`` is ``"gt"``.
    out_dir : path
        Where the label files and the run's settings (``.predict.json``) are written.
    variant : str
        The model variant written.
    source : DetectionSource, optional
        Pre-detections; default (None) our own (``"bank"``).
    options : FitOptions, optional
        The fit's options (default: ``FitOptions()``).
    frames : str, int or iterable of them, optional
        The frames to fit, an int written ``%06d`` as :class:`~wirescene.io.kitti.KittiDataset`
        reads it (:func:`~wirescene.io.kitti.as_frame_ids`; each frame once); default: every
        image of the split.
    resume : bool
        Keep the label files of a previous run with the same settings and fit only the
        missing frames; the previous run's frames must be among ``frames`` (a larger selection
        continues it, a smaller one is refused: its folder would hold frames it did not ask
        for). Without it, ``out_dir`` must not hold label files already.
    workers : int
        Local processes fitting frames in parallel (the files do not depend on it).
    dask_client : distributed.Client, optional
        Fit the frames on this Dask cluster instead of local processes.
    progress : callable
        Wraps the iterable of finished frames (e.g. ``tqdm``).
    notify : callable, optional
        Receives one-line warnings (frames whose calibration looks made for another image
        size); default: standard error.
    json_dir : path, optional
        Also write each frame's ``FRAME.json`` here
        (:func:`wirescene.io.outputs.scene_json`: the cars' 3D boxes and the ground plane, and of a
        fine variant their wireframes and visible vertices).
    pictures_dir : path, optional
        Also write each frame's ``FRAME_overlay.png`` and ``FRAME_bev.png`` here
        (:func:`wirescene.io.outputs.scene_pictures`; a labelled split's cars drawn beside the
        estimates).
    names : mapping of str to str, optional
        How the refusals name ``out_dir``, ``json_dir``, ``pictures_dir`` and ``resume`` (the
        keys of :data:`ARGUMENT_NAMES`), e.g. a command's options ``{"out_dir": "--out", ...,
        "resume": "--resume"}``; default (and for a key the mapping leaves out):
        :data:`ARGUMENT_NAMES`.

    Returns
    -------
    list of str
        The frames fitted by this call (not those kept from a previous run).

    Raises
    ------
    ArgumentError
        Before any fit: ``out_dir``, ``json_dir`` or ``pictures_dir`` is no path, a file, an
        empty path, or a directory that cannot be written or created
        (:func:`wirescene.core.validate.output_dir_problem`); a frame id is a bool, a negative
        int or a float (:func:`~wirescene.io.kitti.as_frame_id`), or ``frames`` holds none (an
        empty submission); ``names`` holds another key, or a value that is no text.
    InputError
        Before any fit: no frame to predict (no image in ``image_2/``, or the folder of frames), a frame
        without its detection file, calibration or image, a malformed detection file, a corrupt or
        truncated image that the frame's fit or pictures read (:func:`~wirescene.eval.runner.check_images_read`), or
        ``out_dir`` holding another run's label files (or, resumed, label files of frames
        outside ``frames``, or a settings' record that cannot be read), or a folder in place of
        that record; ``json_dir`` or ``pictures_dir`` where its files would spoil another folder
        (the label folder, the detections' folder, the images' folder) or holding files of these
        frames not written by a run resumed; with ``pictures_dir``, a malformed label file of a
        labelled split (a missing one is said, its frame's pictures drawn without labels).
    """
    unknown = sorted(map(str, set(names or {}) - set(ARGUMENT_NAMES)))
    if unknown:
        raise ArgumentError("names", f"no argument {unknown[0]!r}; those named: {', '.join(ARGUMENT_NAMES)}")
    odd = [key for key, value in (names or {}).items() if not isinstance(value, str) or not value]
    if odd:
        raise ArgumentError("names", f"{odd[0]!r}: expected a non-empty name, got {names[odd[0]]!r}")
    names = {**ARGUMENT_NAMES, **(names or {})}
    for name, folder in (("out_dir", out_dir), ("json_dir", json_dir), ("pictures_dir", pictures_dir)):
        if folder is None and name != "out_dir":
            continue
        problem = output_dir_problem(folder)
        if problem:  # before any fit, as the command's --out, --json-dir and --pictures
            raise ArgumentError(names[name], problem)
    source = DetectionSource("bank") if source is None else source
    options = FitOptions() if options is None else options
    variant = get_variant(variant).name
    out = Path(out_dir)
    # a submission of no file is refused here, not by the server
    frame_ids = as_frame_ids(frames, some=True) if frames is not None else dataset.require_frames(images=True)
    source.missing_frames(frame_ids)
    extra = {"json_dir": json_dir, "pictures_dir": pictures_dir}
    extra = {name: None if folder is None else Path(folder) for name, folder in extra.items()}
    _folder_problem(out, extra, dataset, source, names)
    # a resumed run's frames keep their files where the first run wrote them: another folder is another run
    config = _config(dataset, variant, source, options,
                     {name: str(f.resolve()) for name, f in extra.items() if f is not None})
    # found now, not where the first frame's labels are written, after its fit
    config_path = settings_record(out, CONFIG_FILE, command="predict")
    existing = sorted(out.glob("*.txt")) if out.is_dir() else []
    if existing and not resume:
        raise InputError(f"already holds {len(existing)} label files; use {names['resume']} to continue that run "
                         "or choose an empty directory", path=out)
    said = {"folders": f"{names['json_dir']} / {names['pictures_dir']}",
            "folders.json_dir": names["json_dir"], "folders.pictures_dir": names["pictures_dir"]}
    # A submission is the folder's *.txt: frames outside this selection would go to the server too.
    stored = (resumed_settings(out, existing, config, config_path, frame_ids, said=said,
                               would="which a submission zipped from it would include") if resume else None)
    if stored != config:  # not a run of these settings resumed (that one's files are its own)
        _others_files(frame_ids, extra, names, resumed=(stored or {}) if resume else None)
    done = {p.stem for p in existing}
    todo = [f for f in frame_ids if f not in done]
    say = notify or notify_stderr
    odd, boxes = check_frames_boxes(dataset, source, todo, labels=source.spec == "gt")
    say_off_centre(odd, len(todo), say)
    if pictures_dir is not None and source.spec != "gt" and dataset.has_labels:
        # the pictures draw a labelled split's cars: a bad label file refused now, not at its frame
        unlabelled = []
        for f in todo:
            if dataset.label_path(f).is_file():
                dataset.labels(f)
            else:
                unlabelled.append(f)
        if unlabelled:
            say(f"warning: {len(unlabelled)} of {len(todo)} frames have no label file in "
                f"{dataset.split_dir / 'label_2'} (e.g. {unlabelled[0]}.txt): their pictures draw the estimates alone")
    boxes.update(source.check_files(dataset, todo, say))  # each frame's boxes, read once
    # a corrupt image refused before the first fit where the run reads it, not at its frame's
    check_images_read(dataset, source, [variant], todo, every=pictures_dir is not None, notify=say, boxes=boxes)
    job = _PredictJob(dataset, variant, source, options, **extra)
    with ExitStack() as stack:
        for k, (frame_id, text, files) in enumerate(progress(fit_frames(job, todo, workers=workers,
                                                                        dask_client=dask_client, stack=stack))):
            if k == 0:  # the settings' record with the first label file: a run failing before leaves nothing
                write_text(config_path, json.dumps(config, indent=1))
            for path, data in files.items():
                write_bytes(path, data)
            write_text(out / f"{frame_id}.txt", text)  # last: a frame with its label file has its other files
    if not todo:
        write_text(config_path, json.dumps(config, indent=1))
    return todo
