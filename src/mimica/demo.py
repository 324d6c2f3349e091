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
from .transfer import ExpressionTransfer, static_vertices

EXPRS = ["happiness", "surprise", "sadness", "anger", "disgust", "jawOpen"]
TARGETS = [("identity A", {"identity000": -0.9, "identity003": 1.2, "identity006": 1.0}),
           ("identity B", {"identity001": 1.0, "identity002": -1.0, "identity009": 1.5}),
           ("identity C (remeshed scan)", {"identity004": 1.0, "identity005": -1.2, "identity008": 1.0})]


def run_demo(out: Path, quick=False, shown: Path | None = None) -> int:
    """Write the demo into `out` (`shown`: the folder named in the messages, if `out` is a stage)."""
    t0 = time.perf_counter()
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    model = ICTModel(ICT_HEAD_VERTICES)
    S = model.mesh
    exprs = EXPRS[:3] if quick else EXPRS
    frames = np.stack([S.vertices + model.delta(model.expression(e)) for e in exprs])
    for e, v in zip(exprs, frames):
        write_mesh(out / "source" / f"{e}.obj", S.with_vertices(v))
    write_mesh(out / "source" / "neutral.obj", S)
    static = static_vertices(S.vertices, frames)
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
        xfer = ExpressionTransfer(S, T, ict_landmarks(S), lt or ict_landmarks(T), static=static)
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
    out = shown or out
    log(f"demo done in {time.perf_counter() - t0:.1f}s: meshes in {out}/, picture {out / 'contact_sheet.png'}")
    log(f"try: mimica transfer {out}/source/neutral.obj {out}/source --target {out}/identity_C/neutral.obj "
        f"--target-landmarks {out}/identity_C/neutral.landmarks.json --out {out}/again")
    return 0
