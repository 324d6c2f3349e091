"""Expression transfer between face meshes (Song et al. §IV-V), with Sumner-Popović DT as baseline.

    xfer = ExpressionTransfer(S, T, source_landmarks, target_landmarks, method="vtc",
                              static=static_vertices(S.vertices, frames))   # precompute
    T_frames = xfer.apply(frames)                                             # (F, n_T, 3)

`ExpressionTransfer` aligns the target to the source by a similarity fit on the landmarks
(Song §V), finds a dense correspondence when the topologies differ (Song §V.A), factors the
target's system once, and hands every result back in the target's own frame, topology and
vertex order.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..align import fit_similarity
from ..correspond import Correspondence, correspond
from ..errors import MimicaError
from ..landmarks import Landmarks
from ..mesh import Mesh
from .core import METHODS, TransferSolver, static_vertices
from .metrics import relative_error, song_vertex_error

__all__ = ["ExpressionTransfer", "TransferSolver", "static_vertices", "relative_error",
           "song_vertex_error", "METHODS"]


class ExpressionTransfer:
    """Precompute for one (source neutral, target neutral) pair, then `apply` to many frames."""

    def __init__(self, source: Mesh, target: Mesh, source_landmarks: Landmarks | None = None,
                 target_landmarks: Landmarks | None = None, method: str = "vtc",
                 static: np.ndarray | None = None, solver_kind: str | None = None):
        self.source, self.target, self.method = source, target, method
        same = source.same_topology(target)
        # an unwelded seam (copies of a vertex, e.g. a uv split) would open under the solve:
        # the target is solved welded and its copies take their vertex's result
        self._copies = None
        if not same:
            welded, index = target.welded()
            if welded is not target:
                if target_landmarks is not None:
                    target_landmarks = Landmarks.snap(welded, target_landmarks.positions(target))
                target, self._copies = welded, index
        if source_landmarks is not None and target_landmarks is not None:
            ls = source_landmarks.positions(source)
            lt = target_landmarks.positions(target)
            self.similarity = fit_similarity(lt, ls, what="landmarks of target and source")
        elif same:
            # same topology: every vertex is a landmark
            self.similarity = fit_similarity(target.vertices, source.vertices)
            ls = lt = None
        else:
            raise MimicaError("source and target have different topologies: landmarks are needed "
                              "on both (68 points each)")
        width = float(np.ptp(source.vertices, axis=0).max())
        self.alignment_residual = self.similarity.residual / max(width, 1e-300)
        aligned = target.with_vertices(self.similarity.apply(target.vertices))
        self.correspondence: Correspondence | None = None
        static = np.zeros(source.n_vertices, bool) if static is None else np.asarray(static, bool)
        if same:
            vmap, matched, fixed = None, None, static
        else:
            self.correspondence = correspond(source, ls, aligned, self.similarity.apply(lt))
            vmap = self.correspondence.matrix(source.triangles)
            matched = self.correspondence.matched
            moving = vmap @ (~static).astype(float)
            fixed = matched & (np.asarray(moving).ravel() == 0)
        self.solver = TransferSolver(source, aligned, method, vertex_map=vmap, matched=matched,
                                     fixed=fixed, solver_kind=solver_kind)
        self._back = self.similarity.inverse()

    def apply(self, frames: np.ndarray, batch: int = 32, workers: int | None = None) -> np.ndarray:
        """Source frames (F, n_S, 3) or (n_S, 3) -> target frames (F, n_T, 3) or (n_T, 3).

        Frames go through in batches (one back-substitution with 3 x batch right-hand
        sides each); batches run on `workers` threads (default: the CPU count), each with
        single-threaded BLAS, which keeps every core busy through all stages.
        """
        frames = np.asarray(frames, dtype=np.float64)
        single = frames.ndim == 2
        f = frames[None] if single else frames
        n = self.target.n_vertices if self._copies is None else int(self._copies.max()) + 1
        out = np.empty((len(f), n, 3))
        starts = range(0, len(f), batch)
        workers = min(workers or os.cpu_count() or 1, len(starts))
        if workers <= 1:
            for i in starts:
                self.solver.apply(f[i:i + batch], self._back, out=out[i:i + batch])
        else:
            from threadpoolctl import threadpool_limits   # here: its import sets KMP_DUPLICATE_LIB_OK
            with threadpool_limits(limits=1), ThreadPoolExecutor(workers) as ex:
                jobs = [ex.submit(self.solver.apply, f[i:i + batch], self._back, out[i:i + batch])
                        for i in starts]
                for j in jobs:
                    j.result()
        if self._copies is not None:
            out = out[:, self._copies]
        return out[0] if single else out
