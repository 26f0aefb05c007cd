"""Write the record of the frames the shipped models were trained on (``data/training_frames.json``).

The frames are those of the shipped part model's ``real_frames`` (the detector bank, the crop
viewpoint classifier and the score calibration were trained on the same 72); each is recorded
by its image's SHA-256 (``wirescene.io.shipped_frames``), which `wirescene eval` compares with
the images it evaluates.

    python benchmarks/record_training_frames.py ../shared/data/kitti --out src/wirescene/data/training_frames.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from wirescene.io.kitti import KittiDataset
from wirescene.io.shipped_frames import training_frames_record, write_training_frames
from wirescene.parts.detector import load_default


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="the KITTI root the shipped models were trained on")
    parser.add_argument("--out", type=Path, required=True, help="record to write")
    args = parser.parse_args(argv)
    frames = load_default().meta["real_frames"].split(",")
    dataset = KittiDataset(args.root)
    record = training_frames_record({f: dataset.image_path(f) for f in frames},
                                    source="image_2/FRAME.png of the real frames the shipped models were trained on "
                                           "(shared/data/kitti, SOURCES.md; the part model's real_frames)")
    write_training_frames(args.out, record)
    print(f"{len(frames)} frames -> {args.out}")


if __name__ == "__main__":
    main()
