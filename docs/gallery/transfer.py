"""Expressions moved onto a head of another topology

Song et al.'s expression transfer: ICT-FaceKit's neutral S and two of its expressions S', and a
target T that shares nothing with them -- the shared real head (MediaPipe's canonical face, 468
vertices, its lips sealed), its landmarks found on renders.  The correspondence and the
factorization are made once; each T' is then one solve.  The sealed lips are cut apart along
their seam, so the surprise opens T's mouth.
"""
import os
import sys
from pathlib import Path

from mimica.data import EXPRESSIONS, ICT_HEAD_VERTICES, ICTModel
from mimica.image import write_image
from mimica.landmarks import ict_landmarks, landmarks_for
from mimica.mesh import read_mesh
from mimica.render import contact_sheet, render_views
from mimica.transfer import ExpressionTransfer

ict = ICTModel(ICT_HEAD_VERTICES)                                       # the head without eyes and mouth
S = ict.mesh
S_expr = [ict.neutral + ict.delta(EXPRESSIONS[e]) for e in ("surprise", "happiness")]
T = read_mesh(Path(os.environ.get("MIMICA_DATA", "../shared/data")) / "real-heads" / "mediapipe-canonical" / "head.obj")
xfer = ExpressionTransfer(S, T, ict_landmarks(S), landmarks_for(T))    # correspondence + factorization, once
T_expr = xfer.apply(S_expr)                                             # (2, n_T, 3), the cut's vertices appended


def front(mesh, v):
    return render_views(mesh, v, views=("front",), size=300)[0]


tiles = [front(S, v) for v in [S.vertices] + S_expr] + [front(xfer.output_mesh, v) for v in [None, *T_expr]]
write_image(sys.argv[1], contact_sheet(tiles, ["S", "S' surprise", "S' happiness", "T (468 vertices)",
                                               "T' surprise", "T' happiness"], columns=3))
