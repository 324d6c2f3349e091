"""Expressions between photos (Song et al. §VI): a source person's neutral photo and expression
photos (or a video of them), a target person's neutral photo -> the target wearing each
expression, written as photos and a contact sheet (or a video)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MimicaError

METHODS = ("shading", "vtc", "eri", "warp")


@dataclass(frozen=True)
class PhotoOptions:
    """How an expression moves between photos; each default is the one every user of it gets.

    Attributes
    ----------
    method : str
        "shading" (the expression's shading on a 3D face under the target's own light), "vtc"
        (Song's vertex-tent luminance transfer, eq. 4), "eri" (expression ratio images, Liu
        2001) or "warp" (the feature-point warp only).
    strength : float or dict
        How much of the expression: 0 none, 1 the source's, up to 2; or per region
        {"brows", "eyes", "nose", "mouth", "jaw", "all": value} (image.analogy.point_strengths).
    mouth : bool
        The source's teeth and mouth interior where it opens its mouth (Song's teeth template).
    head : str
        "still" (the target's head stays) or "follow" (it moves as the source's head does).
    detector : str
        The 68 points' detector: "mediapipe" or "dlib".
    face, source_face : int
        Which face of the target's photo and of the source's photos (0: the largest).
    """
    method: str = "shading"
    strength: float | dict = 1.0
    mouth: bool = True
    head: str = "still"
    detector: str = "mediapipe"
    face: int = 0
    source_face: int = 0


def image_points(img, path, face: int = 0, detector: str = "mediapipe") -> np.ndarray:
    """A photo's 68 feature points: from PHOTO.landmarks.json beside it if present (landmarks.detect2d's
    file), else detected.

    Parameters
    ----------
    img : (h, w, 3) float array
    path : str or Path
        The photo's file.
    face : int
        Which face, by size (0: the largest).
    detector : str
        "mediapipe" or "dlib".

    Returns
    -------
    (68, 2) float array
        Pixels.
    """
    from ..landmarks import detect2d
    side = Path(path).with_suffix(".landmarks.json")
    if side.is_file():
        return detect2d.read_points(side, (img.shape[1], img.shape[0]))
    try:
        return detect2d.detect(img, str(path), face, detector)
    except MimicaError as e:
        if "no face found" in str(e):
            raise MimicaError(f"{e}, named {side.name} beside it (`mimica landmarks` writes one to edit)") from None
        raise MimicaError(f"{e}; `mimica landmarks {Path(path).name} --list` shows them") from None


def tile(img, like) -> np.ndarray:
    """A picture as uint8 at the size of another (contact sheets of photos of different sizes).

    Parameters
    ----------
    img : (h, w, 3) array
    like : (H, W, 3) array

    Returns
    -------
    (H, W, 3) uint8 array
    """
    from PIL import Image
    from ..image.io import to_uint8
    im = Image.fromarray(to_uint8(img))
    h, w = like.shape[:2]
    return np.asarray(im.resize((w, h), Image.BILINEAR)) if im.size != (w, h) else np.asarray(im)


def transfer_photos(source_neutral, target, out, expressions=(), driving=None, options: PhotoOptions | None = None,
                    progress=None, from_neutral=None) -> dict:
    """Move a source person's expressions onto a target person's photo.

    Parameters
    ----------
    source_neutral, target : str or Path
        The source's and the target's neutral photos.
    out : str or Path
        A folder (each expression's photo, named as its source, and sheet.png), or with `driving`
        an .mp4.
    expressions : list of str or Path
        The source's expression photos.
    driving : str or Path, optional
        Or a video (or a folder of frames) of the source person.
    options : PhotoOptions, optional
    progress : callable, optional
        Called as progress(done, total) over a video's frames.
    from_neutral : str or Path, optional
        A photo of the target person at rest (neutral). Given, the target photo may wear an
        expression of its own: each result wears the source's expression from that rest, not added
        to the target's (methods "shading" and "warp").

    Returns
    -------
    dict
        {"kind": "photos" | "video", "count", "setup_s", "transfer_s"} and for photos "files" and
        "sheet".
    """
    from ..image import ImageAnalogy, read_image, write_image
    from ..image.analogy import check_rest_method, point_strengths
    from ..image.io import luminance
    from ..landmarks.detect2d import Tracker
    from ..render import contact_sheet, save_png
    o = options or PhotoOptions()
    if o.method not in METHODS:
        raise MimicaError(f"method {o.method!r}: one of {', '.join(METHODS)}")
    if driving is not None and len(expressions):
        raise MimicaError("give either source expression photos or a driving video, not both")
    if driving is None and not len(expressions):
        raise MimicaError("give source expression photos, or a driving video")
    point_strengths(o.strength if isinstance(o.strength, dict) else {"all": o.strength})   # before the work
    if from_neutral is not None:
        check_rest_method(o.method)                    # before the work
    out = Path(out)
    if driving is not None and out.suffix.lower() != ".mp4":
        raise MimicaError(f"{out}: with a driving video the output is a video; name it .mp4")
    paths = [Path(p) for p in expressions]
    stems = [p.stem for p in paths]
    if len(set(stems)) != len(stems):
        raise MimicaError("two source expressions share a file name; outputs would overwrite each other")
    t0 = time.perf_counter()
    src, tgt = read_image(source_neutral), read_image(target)
    sp = image_points(src, source_neutral, o.source_face, o.detector)
    tp = image_points(tgt, target, o.face, o.detector)
    rest = None
    if from_neutral is not None:
        rest = image_points(read_image(from_neutral), from_neutral, o.face, o.detector)
    an = ImageAnalogy(tgt, tp, mouth=o.mouth, rest_points=rest).setup(o.method)
    src_y = luminance(src)                             # the same source for every expression / frame
    kw = dict(method=o.method, strength=o.strength, head=o.head)
    if driving is not None:
        from ..image.video import VideoWriter, frame_source
        n, fps, frames = frame_source(driving)
        track = Tracker(what=str(driving), face=o.source_face, detector=o.detector)
        t1 = time.perf_counter()
        with VideoWriter(out, fps) as vw:
            for k, f in enumerate(frames):
                vw.write(an.transfer(src_y, sp, f, track(f), **kw).image)
                if progress is not None:
                    progress(k + 1, n)
        return {"kind": "video", "count": vw.n, "setup_s": t1 - t0, "transfer_s": time.perf_counter() - t1}
    exprs = [(p, read_image(p)) for p in paths]
    pts = [image_points(img, p, o.source_face, o.detector) for p, img in exprs]
    t1 = time.perf_counter()
    results = [an.transfer(src_y, sp, img, xp, **kw) for (_, img), xp in zip(exprs, pts)]
    t2 = time.perf_counter()
    cells = [[tile(src, tgt), tile(img, tgt), tile(tgt, tgt), tile(r.image, tgt)] for (_, img), r in zip(exprs, results)]
    sheet = contact_sheet([c for row in cells for c in row], columns=4,
                          labels=[lab for (p, _) in exprs for lab in ("source", p.stem, "target", f"target: {p.stem}")])
    from ..outputs import staged_dir
    with staged_dir(out, {"command": "transfer-image"}) as d:
        for (p, _), r in zip(exprs, results):
            write_image(d / f"{p.stem}.png", r.image)
        save_png(d / "sheet.png", sheet)
    return {"kind": "photos", "count": len(results), "setup_s": t1 - t0, "transfer_s": t2 - t1,
            "files": [out / f"{p.stem}.png" for p, _ in exprs], "sheet": out / "sheet.png"}
