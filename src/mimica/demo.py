"""`make demo`: bundled ICT-FaceKit expressions moved onto other faces; meshes + one contact sheet."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from .data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel
from .landmarks import Landmarks, ict_landmarks, write_landmarks
from .mesh import write_mesh
from .correspond.remesh import resample_face
from .render import contact_sheet, render_mesh, save_png, shared_frame
from .pipeline import TransferOptions, prepare_transfer

EXPRS = ["happiness", "surprise", "sadness", "anger", "disgust", "jawOpen"]
TARGETS = [("identity A", {"identity000": -0.9, "identity003": 1.2, "identity006": 1.0}),
           ("identity B", {"identity001": 1.0, "identity002": -1.0, "identity009": 1.5}),
           ("identity C (remeshed scan)", {"identity004": 1.0, "identity005": -1.2, "identity008": 1.0})]


def run_demo(out: Path, quick=False, shown: Path | None = None) -> int:
    """Write the demo: ICT's expressions moved onto other faces, rendered, and what to try next.

    Parameters
    ----------
    out : Path
        The folder.
    quick : bool
        A smaller demo (the tests').
    shown : Path or None
        The folder named in the messages, if `out` is a stage.

    Returns
    -------
    int
        The exit status.
    """
    t0 = time.perf_counter()
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    model = ICTModel(ICT_HEAD_VERTICES)
    S = model.mesh
    exprs = EXPRS[:3] if quick else EXPRS
    frames = np.stack([S.vertices + model.delta(model.expression(e)) for e in exprs])
    for e, v in zip(exprs, frames):
        write_mesh(out / "source" / f"{e}.obj", S.with_vertices(v))
    write_mesh(out / "source" / "neutral.obj", S)
    rows = [("source (ICT generic)", S, S.vertices, frames)]
    for label, w in TARGETS[: 2 if quick else 3]:
        tv = model.identity(w)
        T = S.with_vertices(tv)
        lt = None
        name = label.split(" (")[0].replace(" ", "_")
        if "remeshed" in label:
            # a scan-like face of its own topology: resampled face area with holes at the
            # eyes, nostrils and mouth; its landmarks go to a JSON file as a user would give them
            face, _ = T.submesh(np.arange(9230))
            rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=12000, seed=3)
            T = rs.mesh
            pts = Landmarks.snap(T, tv[ICT_LANDMARKS_68]).positions(T)
            write_landmarks(out / name / "neutral.landmarks.json", pts)
            lt = Landmarks.snap(T, pts)
        t1 = time.perf_counter()
        xfer, _, _ = prepare_transfer(S, T, frames, TransferOptions(), ict_landmarks(S), lt or ict_landmarks(T))
        res = xfer.apply(frames)
        log(f"{label}: {T.n_vertices} vertices, precompute {time.perf_counter() - t1:.2f}s")
        write_mesh(out / name / "neutral.obj", T)
        for e, v in zip(exprs, res):
            write_mesh(out / name / f"{e}.obj", T.with_vertices(v))
        rows.append((label, T, T.vertices, res))
    tiles, labels = [], []
    for label, mesh, rest, fr in rows:
        frame = shared_frame([rest] + list(fr))
        frame = (frame[0], frame[1] * 0.62)
        for title, v in [("neutral", rest)] + list(zip(exprs, fr)):
            tiles.append(render_mesh(mesh, v, size=(300, 300), frame=(frame[0] + [0, 1.0, 0], frame[1])))
            labels.append(title)
    sheet = contact_sheet(tiles, labels, columns=len(exprs) + 1, row_labels=[r[0] for r in rows],
                          title="mimica: ICT-FaceKit expressions transferred (VTC, Song et al.)")
    save_png(out / "contact_sheet.png", sheet)
    real = _real_head_shapes(out, log)
    out = shown or out
    log(f"demo done in {time.perf_counter() - t0:.1f}s: meshes in {out}/, picture {out / 'contact_sheet.png'}"
        + (f", the real head's 52 ARKit shapes {out / real}" if real else ""))
    log(f"try: mimica transfer {out}/source/neutral.obj {out}/source --target {out}/identity_C/neutral.obj "
        f"--target-landmarks {out}/identity_C/neutral.landmarks.json --out {out}/again")
    return 0


def _real_head_shapes(out: Path, log):
    """The 52 ARKit shapes on the shared real head (another topology, eyes and lips sealed):
    a glTF of morph targets and one picture of them all.  None without the data."""
    import json
    from .data import data_dir
    from .export import ARKIT_52
    from .mesh import read_mesh
    from .pipeline import make_blendshapes
    d = data_dir()
    head_dir = d / "real-heads" / "mediapipe-canonical" if d else None
    if head_dir is None or not (head_dir / "head.obj").is_file():
        log("real head: not in the data directory; skipped")
        return None
    t = time.perf_counter()
    head = read_mesh(head_dir / "head.obj")
    ids = json.loads((head_dir / "head.json").read_text())["landmark_vertices"]
    (out / "real_head").mkdir(parents=True, exist_ok=True)
    # as `mimica blendshapes` writes it: the GLB carries what `animate` reads (its landmarks, its pivot)
    shapes = make_blendshapes(head, out / "real_head" / "arkit_52.glb",
                              landmarks=Landmarks.from_vertex_indices(head, ids)).shapes
    cut = shapes.mesh                          # its sealed lips cut apart: the cut's vertices appended
    frame = shared_frame([head.vertices])
    tiles = [render_mesh(cut, shapes[n], size=(190, 190), frame=frame) for n in ARKIT_52]
    save_png(out / "real_head" / "arkit_52.png",
             contact_sheet(tiles, ARKIT_52, columns=13, title=f"the 52 ARKit shapes on {head_dir.name} "
                           f"({head.n_vertices} vertices, eyes and lips sealed)"))
    log(f"real head ({head.n_vertices} vertices" + (f", lips cut apart: {cut.n_vertices - head.n_vertices} vertices "
        "added" if shapes.mouth is not None else "") + f"): 52 ARKit shapes in {time.perf_counter() - t:.1f}s")
    return Path("real_head") / "arkit_52.png"
