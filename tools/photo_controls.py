"""Draw docs/figures/transfer_image_controls.png: transfer-image's controls on Yale photos.

Row 1, one side or one lip at strength 0 (`--strength eye_left=0,brow_left=0`,
`--strength lip_upper=0`): subject01's surprise onto subject03.
Row 2, `--from-neutral`: subject03's happy photo as the target (it already smiles), its normal
photo as its rest; subject01's surprise added on top of the target's smile, and from the rest.

Run from the project root:  .venv/bin/python tools/photo_controls.py
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.data import data_dir  # noqa: E402
from mimica.image import ImageAnalogy, read_image  # noqa: E402
from mimica.image.io import luminance, to_uint8  # noqa: E402
from mimica.landmarks.detect2d import detect  # noqa: E402
from mimica.render import contact_sheet, save_png  # noqa: E402


def main():
    yale = data_dir() / "yalefaces"
    photo = {k: read_image(yale / f"{k}.gif") for k in ("subject01.normal", "subject01.surprised",
                                                       "subject03.normal", "subject03.happy")}
    pts = {k: detect(v) for k, v in photo.items()}
    s, sp = luminance(photo["subject01.normal"]), pts["subject01.normal"]
    x, xp = luminance(photo["subject01.surprised"]), pts["subject01.surprised"]
    neutral, happy = photo["subject03.normal"], photo["subject03.happy"]
    plain = ImageAnalogy(neutral, pts["subject03.normal"])
    row1 = [photo["subject01.surprised"], neutral] + [plain.transfer(s, sp, x, xp, strength=a).image for a in (
        1.0, {"eye_left": 0.0, "brow_left": 0.0}, {"lip_upper": 0.0})]
    stacked = ImageAnalogy(happy, pts["subject03.happy"]).transfer(s, sp, x, xp).image
    rest = ImageAnalogy(happy, pts["subject03.happy"], rest_points=pts["subject03.normal"]).transfer(s, sp, x, xp).image
    row2 = [neutral, happy, photo["subject01.surprised"], stacked, rest]
    labels = ["source: surprised", "target", "all 1", "eye_left=0,brow_left=0", "lip_upper=0",
              "target's rest", "target (smiles)", "source: surprised", "added to its smile", "--from-neutral"]
    out = ROOT / "docs" / "figures" / "transfer_image_controls.png"
    crop = (slice(25, 235), slice(70, 250))                  # the faces, large enough to see an eye
    save_png(out, contact_sheet([to_uint8(i[crop]) for i in row1 + row2], columns=5, labels=labels))
    print(out)


if __name__ == "__main__":
    main()
