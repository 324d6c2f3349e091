"""`mimica landmarks`: find the 68 feature points on a photo or a mesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ._common import DETECTOR_HELP, _say


def _mesh_landmarks(a, path: Path) -> int:
    """A mesh's 68 landmarks, found on its renders (landmarks.detect3d)."""
    if a.list or a.out is None:
        raise MimicaError(f"{path}: a mesh has one face; write its landmarks with --out LANDMARKS.json")
    from ..landmarks import write_landmarks
    from ..landmarks.detect3d import detect_mesh
    from ..mesh import read_mesh
    mesh = read_mesh(path)
    pts, view = detect_mesh(mesh, what=str(path))
    if a.show:
        from ..render import face_framing, project, render_mesh, save_png
        fr = face_framing(pts)
        img = render_mesh(mesh, size=(640, 640), frame=fr)
        xy, _ = project(pts, fr, (640, 640))
        save_png(Path(a.show), _draw_points(img, xy))
    write_landmarks(a.out, pts)
    _say(f"68 landmarks found from the view yaw {view[0]}, pitch {view[1]} -> {a.out}")
    return 0


def cmd_landmarks(a):
    """`mimica landmarks`: the 68 feature points found on a photo or a mesh, written as JSON (and a
    picture).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..image import read_image, write_image
    from ..landmarks import detect2d
    from ..image.io import to_uint8
    from ..mesh import MESH_SUFFIXES
    path = Path(a.face)
    if path.suffix.lower() in MESH_SUFFIXES:
        return _mesh_landmarks(a, path)
    img = read_image(path)
    if a.list:
        boxes = detect2d.face_boxes(img, a.detector)
        _say(f"{path}: {len(boxes)} face(s), by size" + "".join(
            f"; {i}: {r - l}x{b - t} px at ({(l + r) // 2}, {(t + b) // 2})" for i, (l, t, r, b) in enumerate(boxes)))
        return 0
    if a.out is None:
        raise MimicaError("landmarks: --out LANDMARKS.json is needed (or --list)")
    try:
        pts = detect2d.detect(img, str(path), a.face_number, a.detector)
    except MimicaError as e:
        raise MimicaError(f"{e}; --list shows them" if "no face found" not in str(e) else str(e)) from None
    if a.show:
        write_image(Path(a.show), _draw_points(to_uint8(img), pts))
    detect2d.write_points(a.out, pts, image=path.name, size=(img.shape[1], img.shape[0]))
    _say(f"68 points -> {a.out} (pixel coordinates; edit and rerun `transfer-image`, which reads "
         f"PHOTO.landmarks.json beside each photo)")
    return 0


def _draw_points(img, xy):
    from PIL import Image, ImageDraw
    im = Image.fromarray(np.asarray(img, np.uint8)).convert("RGB")
    d = ImageDraw.Draw(im)
    r = max(1.5, im.width / 250)
    for i, (x, y) in enumerate(xy):
        col = (255, 60, 40) if i < 17 else (40, 200, 255) if i < 27 else (255, 220, 0) if i < 36 else (80, 255, 80) if i < 48 else (255, 80, 255)
        d.ellipse([x - r, y - r, x + r, y + r], fill=col)
    return np.asarray(im)


def add_args(sub) -> None:
    """Put `mimica landmarks` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    lm = sub.add_parser("landmarks", help="find the 68 feature points on a photo or a mesh")
    lm.add_argument("face", help="photo (JPEG/PNG/GIF...) or mesh (OBJ/PLY/glTF)")
    lm.add_argument("-o", "--out", help="landmark JSON to write (pixels for photos, 3D for meshes)")
    lm.add_argument("--list", action="store_true", help="photos: list the faces found (numbered by size)")
    lm.add_argument("--face", type=int, default=0, dest="face_number",
                    help="photos: which face (0: the largest; --list numbers them)")
    lm.add_argument("--show", metavar="PNG", help="also draw the points")
    lm.add_argument("--detector", choices=["dlib", "mediapipe"], default="mediapipe", help=DETECTOR_HELP)
    lm.set_defaults(func=cmd_landmarks)


run = cmd_landmarks
