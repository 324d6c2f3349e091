"""Automatic 3D landmarks (for meshes of other topologies with no landmark file): render the
mesh from the front, find the 68 points in the picture with the 2D detector, and cast each
back onto the visible surface along the view ray."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..mesh import Mesh
from . import detect2d

# views tried in turn until a face is found: (yaw, pitch) in degrees; the first is the
# usual convention (y up, face toward +z)
VIEWS = [(0, 0), (180, 0), (90, 0), (-90, 0), (0, 90), (0, -90)]


def _frame(v, view):
    from ..image.raster import framing
    c, half = framing(v, *view, margin=1.1)
    return c, half


def render_for_detection(mesh: Mesh, vertices=None, view=(0, 0), size=640, frame=None):
    """A picture of a mesh for the face detector (grey, lit from the front and a little above).

    Parameters
    ----------
    mesh : Mesh
    vertices : (n, 3) float array or None
        Positions to draw (None: the mesh's).
    view : tuple of float
        (yaw, pitch) degrees.
    size : int
        The square picture's side, pixels.
    frame : tuple or None
        (center, half extent) (None: the mesh framed).

    Returns
    -------
    img : (size, size, 3) uint8 array
    frame : tuple
        The framing used.
    xy : (n, 2) float array
        The vertices' pixels.
    cam : (n, 3) float array
        Their camera-space positions.
    """
    from ..image.raster import project, render_mesh
    v = mesh.vertices if vertices is None else np.asarray(vertices)
    frame = frame or _frame(v, view)
    img = render_mesh(mesh, v, size=(size, size), yaw=view[0], pitch=view[1], frame=frame,
                      light=(0.0, 0.35, 1.0), background=(70, 70, 70))
    xy, cam = project(v, frame, (size, size), *view)
    return img, frame, xy, cam


def front_ids(mesh: Mesh, xy, cam, size, sign=1.0):
    """The triangle seen at each pixel with back faces culled, so that a point in an eye or mouth
    opening sees no surface (rather than the inside of the back of the head).

    Parameters
    ----------
    mesh : Mesh
    xy : (n, 2) float array
        The vertices' pixels.
    cam : (n, 3) float array
        Their camera-space positions.
    size : int
    sign : float
        1 for outward normals, -1 for a mesh that is inside out.

    Returns
    -------
    (size, size) int array
        Indices of the mesh's triangles; -1 = nothing.
    """
    from ..image.raster import rasterize
    tris = mesh.triangles
    p = xy[tris]
    # pixel y points down: a counter-clockwise triangle (as seen) has negative signed area here
    area = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])
    keep = np.nonzero(sign * area < 0)[0]
    tid, _ = rasterize(xy, cam[:, 2], tris[keep], size, size)
    return np.where(tid >= 0, keep[np.maximum(tid, 0)], -1)


def cast_back(points2d, mesh: Mesh, xy, tri_id, vertices=None) -> np.ndarray:
    """Surface points under 2D pixel positions: the visible triangle at the pixel, exact barycentrics
    of the point in its projection.

    Parameters
    ----------
    points2d : (m, 2) float array
    mesh : Mesh
    xy : (n, 2) float array
        The vertices' pixels.
    tri_id : (h, w) int array
        front_ids'.
    vertices : (n, 3) float array or None
        The positions drawn (None: the mesh's).

    Returns
    -------
    (m, 3) float array
        NaN where no surface is seen.
    """
    v = mesh.vertices if vertices is None else np.asarray(vertices)
    tris = mesh.triangles
    h, w = tri_id.shape
    out = np.full((len(points2d), 3), np.nan)
    for i, (px, py) in enumerate(np.asarray(points2d, float)):
        ix, iy = int(round(px)), int(round(py))
        best = None
        for r in range(0, 24):                      # nearest covered pixel (openings, silhouette)
            ys, xs = np.mgrid[max(iy - r, 0):min(iy + r + 1, h), max(ix - r, 0):min(ix + r + 1, w)]
            ok = tri_id[ys, xs] >= 0
            if ok.any():
                d = (xs[ok] - px) ** 2 + (ys[ok] - py) ** 2
                k = np.argmin(d)
                best = tri_id[ys[ok][k], xs[ok][k]]
                break
        if best is None:
            continue
        a, b, c = xy[tris[best]]
        m = np.array([b - a, c - a]).T
        try:
            l1, l2 = np.linalg.solve(m, np.array([px, py]) - a)
        except np.linalg.LinAlgError:
            l1 = l2 = 1 / 3
        l1, l2 = np.clip(l1, 0, 1), np.clip(l2, 0, 1)
        if l1 + l2 > 1:
            l1, l2 = l1 / (l1 + l2), l2 / (l1 + l2)
        t = tris[best]
        out[i] = (1 - l1 - l2) * v[t[0]] + l1 * v[t[1]] + l2 * v[t[2]]
    return out


OFFSETS_FILE = Path(__file__).with_name("detect3d_offsets.json")


@lru_cache(maxsize=1)
def _offsets():
    """Per-landmark correction from the detector's markup convention (the visible eyelid and
    jaw outline in a photo) to the vertex markup of ICT-FaceKit's 68 landmarks, in units of the
    eye-to-eye distance in the eye-line frame; fitted by tools/calibrate_landmarks3d.py on the
    even-numbered ICT identities (the odd ones are held out for the error figure)."""
    if not OFFSETS_FILE.is_file():
        return None
    return np.asarray(json.loads(OFFSETS_FILE.read_text())["offsets"], float)


def eye_frame(p2):
    """The eye-to-eye distance and the unit vectors across and down the face, from 2D points.

    Parameters
    ----------
    p2 : (68, 2) float array

    Returns
    -------
    iod : float
    across, down : (2,) float arrays
    """
    across = p2[42:48].mean(0) - p2[36:42].mean(0)
    iod = float(np.linalg.norm(across))
    ex = across / max(iod, 1e-9)
    return iod, ex, np.array([-ex[1], ex[0]])


def calibrate(p2, offsets=None) -> np.ndarray:
    """2D points moved by the per-landmark offsets from the detector's markup to ICT-FaceKit's
    vertex markup (_offsets), in eye-frame units.

    Parameters
    ----------
    p2 : (68, 2) float array
    offsets : (68, 2) float array or None
        None: the fitted ones (detect3d_offsets.json).

    Returns
    -------
    (68, 2) float array
    """
    off = _offsets() if offsets is None else offsets
    if off is None:
        return p2
    iod, ex, ey = eye_frame(p2)
    return p2 + iod * (off[:, :1] * ex + off[:, 1:] * ey)


def detect_mesh(mesh: Mesh, vertices=None, what="mesh", size=640, view=None, calibrated=True):
    """The 68 landmarks of a mesh of any topology, found by dlib on renders and cast back onto the
    surface (the front first, then the back, the sides, top and bottom).

    Parameters
    ----------
    mesh : Mesh
    vertices : (n, 3) float array or None
    what : str
        How messages name the mesh.
    size : int
        The renders' side, pixels.
    view : tuple or None
        Only this (yaw, pitch).
    calibrated : bool
        Apply calibrate's offsets.

    Returns
    -------
    points : (68, 3) float array
    view : tuple
        The (yaw, pitch) that found them.
    """
    views = [view] if view is not None else VIEWS
    for vw in views:
        img, frame, xy, cam = render_for_detection(mesh, vertices, vw, size)
        boxes = detect2d.detect_faces(img, upsample=0)
        if boxes:
            p2 = detect2d.fit_points(img, boxes[0])
            if calibrated:
                p2 = calibrate(p2)
            for sign in (1.0, -1.0):                 # outward normals, else the mesh is inside out
                tri_id = front_ids(mesh, xy, cam, size, sign)
                ix = np.clip(np.round(p2).astype(int), 0, size - 1)
                if (tri_id[ix[:, 1], ix[:, 0]] >= 0).mean() > 0.5:
                    break
            p3 = cast_back(p2, mesh, xy, tri_id, vertices)
            if np.isfinite(p3).all(1).sum() >= 60:
                return p3, vw
    raise MimicaError(f"{what}: no face found in renders from the front, back, sides, top or bottom; "
                      "give its 68 landmarks in a file (JSON: {\"scheme\": \"ibug68\", \"points\": [[x,y,z], ...]})")
