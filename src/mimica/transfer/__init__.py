"""Expression transfer between face meshes (Song et al. §IV-V), with Sumner-Popović DT as baseline.

    xfer = ExpressionTransfer(S, T, source_landmarks, target_landmarks, TransferSettings(method="vtc"),
                              static=static_vertices(S.vertices, frames))   # precompute
    T_frames = xfer.apply(frames)                                             # (F, n_T, 3)

`ExpressionTransfer` aligns the target to the source by a similarity fit on the landmarks
(Song §V), finds a dense correspondence when the topologies differ (Song §V.A), factors the
target's system once, and hands every result back in the target's own frame, topology and
vertex order.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace

import numpy as np

from ..align import fit_similarity
from ..correspond import Correspondence, correspond
from ..errors import MimicaError
from ..landmarks import Landmarks
from ..mesh import Mesh
from ..parallel import cores, one_blas_thread
from .core import ANCHOR, DT_STABILIZER, METHODS, TransferSolver, static_vertices
from .metrics import relative_error, song_vertex_error

BASIS_FRAMES = 128        # sequences this long go through their basis by default
BASIS_CHECK = 4           # frames solved one by one to check it (where its tips' fit misses most)
# ... which must agree within this share of the performance's largest motion: the 1e-3 promised
# over 1.67.  The checked frames' largest deviation read 0.90-1.0 of the whole sequence's on seven
# takes (bench/batch.py's 300 frames: 2.82e-4 both; onto a 6k remesh 4.48e-4 checked, 4.43e-4 in
# all; 12 shapes 3.55e-4, 3.44e-4), and 1/1.72 at worst with the tips' tolerance doubled.  (Four
# frames spread evenly read a quarter of it: 7.6e-5 against 2.8e-4; the threshold was 2.5e-4.)
BASIS_DEVIATION = 6e-4

__all__ = ["ExpressionTransfer", "TransferSettings", "TransferSolver", "static_vertices", "relative_error", "BASIS_FRAMES",
           "song_vertex_error", "METHODS"]


@dataclass(frozen=True)
class TransferSettings:
    """How `ExpressionTransfer` solves a (source, target) pair; each default is the one every
    caller gets.  `dataclasses.replace(settings, method="dt")` makes a variant.

    Attributes
    ----------
    method : str
        "vtc" (Song et al.'s vertex-tent coordinates) or "dt" (Sumner and Popovic's deformation
        transfer).
    match : str
        How target vertices find their source partners across topologies (correspond.METHODS):
        "nicp", a non-rigid registration of the source onto the target, or "cylinder", Song et
        al.'s cylinder map.
    solver_kind : str or None
        The sparse solver (solver.SPDSolver; None: the best installed).
    parts : bool
        Split both heads into their parts (correspond.parts): skin to skin, eyeballs, teeth and
        tongue rigid, lashes and shells with the skin (transfer.parts).
    cut_mouth : bool
        Cut a target's sealed lips apart (correspond.mouth): the results have the cut's copies
        appended.
    cut_eyes : bool
        A target whose eyes are one surface with its lids has each eye cut loose along its lid
        margin (correspond.eyes), the inside then its eye, rigid, which the lids close over
        (the copies follow the mouth's).
    weld : bool
        Solve a target whose seams are copies of a vertex (uv splits) welded.
    relayout : bool
        A target that is the source's own mesh in another vertex layout (a DCC's export,
        correspond.layout) is solved on the source's topology.
    lids : bool
        The target's open eyes close as far as the source's do (transfer.contacts).
    fill : bool
        Skin whose correspondence has low confidence takes its motion from the skin around it
        (transfer.fill).
    stabilize : bool
        VTC's energy gets a small per-triangle (DT) term (core.DT_STABILIZER), which keeps
        vertices in sliver one-rings from drifting; off gives Song's energy alone.
    anchor : float
        How firmly each vertex is held to its rest position plus the source's displacement at its
        partner (core.ANCHOR, weighed against the elements' energy at the face's scale): long
        waves of the motion come from the source, short ones from the deformation; 0 gives Song's
        energy alone (a vanishing weight that only pins the translation).
    """
    method: str = "vtc"
    match: str = "nicp"
    solver_kind: str | None = None
    parts: bool = True
    cut_mouth: bool = True
    cut_eyes: bool = True
    weld: bool = True
    relayout: bool = True
    lids: bool = True
    fill: bool = True
    stabilize: bool = True
    anchor: float = ANCHOR

    def __post_init__(self):
        from ..correspond import METHODS as MATCHES
        if self.method not in METHODS:
            raise MimicaError(f"transfer method {self.method!r}: use one of {', '.join(METHODS)}")
        if self.match not in MATCHES:
            raise MimicaError(f"correspondence {self.match!r}: use one of {', '.join(MATCHES)}")
        if not (np.isfinite(self.anchor) and self.anchor >= 0):
            raise MimicaError(f"transfer anchor {self.anchor!r}: give a weight of 0 or more")


SETTINGS = frozenset(f.name for f in fields(TransferSettings))


class ExpressionTransfer:
    """Song et al.'s expression transfer for one (source neutral, target neutral) pair: the
    correspondence and the factorization made once, then `apply` moves any number of source
    frames onto the target.

    Parameters
    ----------
    source, target : Mesh
        The source neutral (n_S vertices) and the target neutral (any topology).
    source_landmarks, target_landmarks : Landmarks or None
        Their 68 landmarks; needed across topologies (the target's may be found on renders:
        landmarks.landmarks_for).  On one topology every vertex is its own partner.
    settings : TransferSettings or None
        How the pair is solved (None: the defaults).
    static : (n_S,) bool array or None
        Source vertices no frame moves (transfer.static_vertices): held still on the target.
    inward : (n_T, 3) float array or None
        Where each target vertex's correspondence is looked up, as offsets (the two sides of a
        cut seam look inside their own lip).
    **changes
        Any field of TransferSettings, changed from `settings` (`method="dt"`).

    Attributes
    ----------
    settings : TransferSettings
        The settings used.
    output_mesh : Mesh
        The mesh the results belong to: the target in its own vertex order, any cut's copies
        after its vertices.
    correspondence : Correspondence or None
        The dense map (across topologies).
    similarity : Similarity
        The target's alignment onto the source; `alignment_residual` its residual over the
        face's size.
    parts : tuple of Parts or None
        The source's and the target's parts, where either has more than skin.
    mouth, eye_cut : MouthCut or EyeCut or None
        The cuts made; `mouth_uncut` and `eyes_uncut` say why sealed ones were left.
    relaid : bool
        The target was the source's mesh in another layout, solved on the source's topology.
    basis_report : dict
        What the last `apply` did with a long sequence's basis.
    """

    def __init__(self, source: Mesh, target: Mesh, source_landmarks: Landmarks | None = None,
                 target_landmarks: Landmarks | None = None, settings: TransferSettings | None = None, *,
                 static: np.ndarray | None = None, inward: np.ndarray | None = None, **changes):
        if settings is not None and not isinstance(settings, TransferSettings):
            raise TypeError("ExpressionTransfer: settings must be a TransferSettings (a method is given "
                            "as method=...)")
        unknown = set(changes) - SETTINGS
        if unknown:
            raise TypeError(f"ExpressionTransfer: no setting {', '.join(sorted(unknown))} "
                            f"(TransferSettings has {', '.join(sorted(SETTINGS))})")
        s = self.settings = replace(settings or TransferSettings(), **changes)
        self.source = source
        self.basis_report = {"used": False, "why": "not applied yet"}
        same = source.same_topology(target)
        self.parts = self._parts = self.mouth = self._lids = self._fill = None
        self.mouth_uncut = None           # sealed lips whose seam was not found (correspond.mouth.MouthCut.why)
        self.eye_cut, self.eyes_uncut = None, {}  # one-surface eyes cut open (correspond.eyes), or why not
        self.output_mesh = target
        # user vertex -> solved vertex, and the solved vertices appended after the user's
        self._copies, self._appended = None, 0
        self.relaid = False
        if not same and s.relayout:
            target, target_landmarks, same = self._relayout(source, target, source_landmarks, target_landmarks)
        if not same and s.weld:
            # an unwelded seam (copies of a vertex, e.g. a uv split) would open under the solve
            welded, index = target.welded()
            if welded is not target:
                if target_landmarks is not None:
                    target_landmarks = Landmarks.snap(welded, target_landmarks.positions(target))
                target, self._copies = welded, index
        if not same and target_landmarks is not None:
            target, target_landmarks, inward = self._cut(target, target_landmarks, inward, source_landmarks)
        self._mouth_appended = self._appended - (0 if self.eye_cut is None else len(self.eye_cut.copies_of))
        self.target = target
        if s.parts and not same and source_landmarks is not None and target_landmarks is not None:
            from ..correspond.parts import split_parts
            ls_pos, lt_pos = source_landmarks.positions(source), target_landmarks.positions(target)
            eyes = self.eye_cut.eyes if self.eye_cut is not None else None
            ps, pt = split_parts(source, ls_pos), split_parts(target, lt_pos, eyes=eyes)
            if not (ps.only_skin and pt.only_skin):
                self._init_parts(ps, pt, ls_pos, lt_pos, static, inward)
                return
        self._init_solve(source, target, source_landmarks, target_landmarks, same, static, inward)

    @property
    def method(self) -> str:
        """"vtc" or "dt" (settings.method)."""
        return self.settings.method

    @property
    def match(self) -> str:
        """How the correspondence was found (settings.match)."""
        return self.settings.match

    def _relayout(self, source, target, source_landmarks, target_landmarks):
        """The source's own mesh in another vertex layout (a DCC's export): solved on the
        source's topology, each user vertex taking its source vertex's result."""
        from ..correspond.layout import same_mesh
        of = same_mesh(source, target)
        if of is None:
            return target, target_landmarks, False
        at = np.full(source.n_vertices, -1)
        at[of[::-1]] = np.arange(len(of))[::-1]
        twins = np.nonzero(at < 0)[0]            # a source vertex the file welded to its twin
        if len(twins):
            from scipy.spatial import cKDTree
            reached = np.nonzero(at >= 0)[0]
            at[twins] = at[reached[cKDTree(source.vertices[reached]).query(source.vertices[twins])[1]]]
        self._copies, self.relaid = of, True
        # the source's landmarks, now on the same topology
        return source.with_vertices(target.vertices[at]), (None if target_landmarks is None else source_landmarks), True

    def _cut(self, target, target_landmarks, inward, source_landmarks=None):
        """A target's sealed lips cut apart and its one-surface eyes cut loose, as settings say
        (found landmarks put on a sealed eye's margin by the source's eyes as templates)."""
        if self.settings.cut_mouth:
            from ..correspond.mouth import cut_mouth as cut
            mc = cut(target, target_landmarks.positions(target))
            self.mouth_uncut = mc if mc.why else None
            if mc.cut:
                self.mouth = mc
                self._appended = len(mc.copies_of)
                self.output_mesh = _user_cut(self.output_mesh, target, mc)
                inward = mc.inward             # the landmarks stay: the cut keeps every triangle
                target = mc.mesh
        if self.settings.cut_eyes:
            from ..correspond.eyes import cut_eyes as cut_e
            template = None                    # made only where a sealed eye needs it
            if target_landmarks.found and source_landmarks is not None:
                template = lambda: _eye_template(self.source, source_landmarks)  # noqa: E731
            ec = cut_e(target, target_landmarks.positions(target), found=target_landmarks.found, template=template)
            self.eyes_uncut = ec.why
            if ec.cut:
                self.eye_cut = ec
                self._appended += len(ec.copies_of)
                self.output_mesh = _user_cut(self.output_mesh, target, ec)
                if inward is not None:
                    inward = np.vstack([inward, np.zeros((len(ec.copies_of), 3))])
                target_landmarks = _off_the_eyes(ec, ec.landmarks)   # found ones put on the margins
                target = ec.mesh
        return target, target_landmarks, inward

    def _init_solve(self, source, target, source_landmarks, target_landmarks, same, static, inward):
        """The alignment, the correspondence (across topologies) and the factored system."""
        s = self.settings
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
            lookup = None if inward is None else (aligned.vertices + self.similarity.scale
                                                  * np.asarray(inward) @ self.similarity.rotation.T)
            self.correspondence = correspond(source, ls, aligned, self.similarity.apply(lt), method=s.match,
                                             lookup=lookup)
            vmap = self.correspondence.matrix(source.triangles)
            matched = self.correspondence.matched
            moving = vmap @ (~static).astype(float)
            fixed = matched & (np.asarray(moving).ravel() == 0)
        # across topologies VTC is steadied by a small per-triangle term (core.DT_STABILIZER)
        self.solver = TransferSolver(source, aligned, s.method, vertex_map=vmap, matched=matched,
                                     fixed=fixed, solver_kind=s.solver_kind,
                                     dt_weight=DT_STABILIZER if s.stabilize and not same else 0.0,
                                     anchor=s.anchor)
        self._back = self.similarity.inverse()
        if s.fill and self.correspondence is not None and self.correspondence.confidence is not None:
            from .fill import LowConfidenceFill
            lf = LowConfidenceFill(target, self.correspondence.confidence, self.correspondence.LOW)
            self._fill = lf if lf.ok else None
        if s.lids and not same and lt is not None:
            from .contacts import LidContacts
            lc = LidContacts(target, lt, ls)
            if lc.eyes:
                self._lids, self._source_landmarks = lc, source_landmarks

    def _init_parts(self, ps, pt, ls_pos, lt_pos, static, inward=None):
        """The skin-to-skin transfer and the motion of the other parts (transfer.parts)."""
        from .parts import PartMotion
        s_skin, s_idx = self.source.submesh(ps.skin_faces)
        t_skin, t_idx = self.target.submesh(pt.skin_faces)
        self.parts = (ps, self._user_parts(pt))
        self._parts_role = pt.role
        st = None if static is None else np.asarray(static, bool)[s_idx]
        skin_only = replace(self.settings, parts=False, cut_mouth=False, weld=False, relayout=False, cut_eyes=False)
        self._skin = ExpressionTransfer(s_skin, t_skin, Landmarks.snap(s_skin, ls_pos), Landmarks.snap(t_skin, lt_pos),
                                        skin_only, static=st,
                                        inward=None if inward is None else np.asarray(inward)[t_idx])
        self._source_skin, self._target_skin = s_idx, t_idx
        self.similarity = self._skin.similarity
        self.alignment_residual = self._skin.alignment_residual
        self.correspondence = self._skin.correspondence
        match = None
        if self.correspondence is not None:       # each target skin vertex's place on the source
            c = self.correspondence
            match = (np.where(c.matched[:, None], s_idx[s_skin.triangles[np.maximum(c.triangle, 0)]], -1), c.bary)
        self._parts = PartMotion(self.source, ps, self.target, pt, t_skin, t_idx, self.similarity, ls_pos, match)

    def apply(self, frames: np.ndarray, batch: int = 32, workers: int | None = None,
              basis: bool | None = None) -> np.ndarray:
        """Source frames (F, n_S, 3) or (n_S, 3) -> target frames (F, n_T, 3) or (n_T, 3).

        Frames go through in batches (one back-substitution with 3 x batch right-hand
        sides each); batches run on `workers` threads (default: the CPU count), each with
        single-threaded BLAS, which keeps every core busy through all stages.

        basis: a sequence whose motion lies in a few shapes goes through their basis
        (TransferSolver.apply_basis: one back-substitution per basis shape), kept only when the
        few frames its tips' interpolation misses most, solved one by one, agree within
        BASIS_DEVIATION of the motion; `basis_report` says what happened.  Default (None):
        sequences of BASIS_FRAMES frames or more (bench/batch.py's 300 frames: 1,600-2,200
        against 410-470 frames/s, 2.8e-4 of the motion off; 96 frames: 646 against 379; 64: slower).
        """
        frames = np.asarray(frames, dtype=np.float64)
        single = frames.ndim == 2
        f = frames[None] if single else frames
        if basis is None:
            basis = len(f) >= BASIS_FRAMES
        if self._parts is not None:
            skin = self._skin.apply(f[:, self._source_skin], batch, workers, basis)
            self.basis_report = self._skin.basis_report
            out = self._to_user(self._parts.apply(f, skin))
            return out[0] if single else out
        out = None
        self.basis_report = {"used": False, "why": "frame by frame"}
        if basis:
            out = self._through_basis(f)
        if out is None:
            out = np.empty((len(f), self.target.n_vertices, 3))
            starts = range(0, len(f), batch)
            workers = min(workers or cores(), len(starts))
            if workers <= 1:
                for i in starts:
                    self.solver.apply(f[i:i + batch], self._back, out=out[i:i + batch])
            else:
                with one_blas_thread(), ThreadPoolExecutor(workers) as ex:
                    jobs = [ex.submit(self.solver.apply, f[i:i + batch], self._back, out[i:i + batch])
                            for i in starts]
                    for j in jobs:
                        j.result()
        if self._fill is not None:
            out = self._fill.apply(out)
        if self._lids is not None:
            out = self._lids.apply(self._source_landmarks.positions_in(self.source, f), out)
        out = self._to_user(out)
        return out[0] if single else out

    def _through_basis(self, f: np.ndarray):
        """The frames through their basis, or None (not low-rank, or off by more than
        BASIS_DEVIATION on the frames checked one by one)."""
        out = self.solver.apply_basis(f, similarity=self._back, check=BASIS_CHECK)
        if out is None:
            self.basis_report = {"used": False, "why": self.solver.basis_stats["why"]}
            return None
        # checked where the tips' interpolation misses most (frames off the training ones, solved
        # one by one in the basis's back-substitution)
        st = self.solver.basis_stats
        pick, exact, seen = st["checked"], st["exact"], st["trained"][::4]
        # against the performance's largest motion, as far as the checked frames and a quarter of
        # the training ones show it (a lower bound: the check errs on the strict side), and no
        # less than 1e-6 of the face's size (frames at rest move by rounding alone)
        t = self.target.vertices
        motion = max(_longest(exact - t), _longest(out[seen] - t), 1e-6 * float(np.ptp(t, axis=0).max()))
        dev = _longest(out[pick] - exact) / motion
        self.basis_report = {"used": dev <= BASIS_DEVIATION, "deviation": dev, "checked": len(pick),
                             "why": "through the basis" if dev <= BASIS_DEVIATION else
                             f"the basis was off by {dev:.1e} of the motion on the frames checked"}
        return out if dev <= BASIS_DEVIATION else None

    @property
    def paired_eyes(self) -> list[str]:
        """The target's eyes whose lid rims the contacts pair ("right", "left")."""
        inner = self._skin if self._parts is not None else self
        return [] if inner._lids is None else list(inner._lids.eyes)

    def vertex_report(self) -> dict:
        """Per vertex of `output_mesh`, for pictures and reports: 'role' (index into
        correspond.parts.ROLES; all skin without parts), 'matched' (skin with a source partner),
        'seam' (the cut mouth's two sides), 'looked' (where sealed lips were looked for a seam
        and none was cut), 'rim' (the lid rims the contacts pair), 'confidence' (of the skin's
        correspondence, in [0, 1]; 1 elsewhere and on the same topology; 0 where unmatched)."""
        from ..correspond.parts import ROLES
        n = self.target.n_vertices
        role = np.full(n, ROLES.index("skin"))
        matched, seam, rim = np.ones(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        confidence = np.ones(n)
        inner, idx = self, np.arange(n)
        if self._parts is not None:
            role = self._parts_role
            inner, idx = self._skin, self._target_skin
        if inner.correspondence is not None:
            matched[idx] = inner.correspondence.matched
            c = inner.correspondence.confidence
            confidence[idx] = inner.correspondence.matched if c is None else c
        if inner._lids is not None:
            for eye in inner._lids.eyes.values():
                rim[idx[np.r_[eye.upper, eye.lo0, eye.lo1]]] = True
        if self.mouth is not None:
            seam[self.mouth.seam] = True
            seam[n - self._appended: n - self._appended + self._mouth_appended] = True
        if self.eye_cut is not None:
            for loop in self.eye_cut.rims.values():
                rim[loop] = True
            rim[n - self._appended + self._mouth_appended:] = True
        looked = np.zeros(n, bool)
        if self.mouth_uncut is not None:
            looked[self.mouth_uncut.seam] = True
        def user(a):                     # solved vertices -> the user's, as _to_user
            return a if self._copies is None else np.r_[a[self._copies], a[n - self._appended:]]
        return {"role": user(role), "matched": user(matched), "seam": user(seam), "looked": user(looked),
                "rim": user(rim), "confidence": user(confidence)}

    def _user_parts(self, pt):
        """The target's parts on the user's vertices (and a cut's copies after them)."""
        if self._copies is None:
            return pt
        from ..correspond.parts import Parts
        n = self.target.n_vertices
        idx = np.r_[self._copies, np.arange(n - self._appended, n)]
        return Parts(pt.label[idx], pt.names, pt.role[idx], pt.skin_faces,
                     None if pt.jaw_weight is None else pt.jaw_weight[idx])

    def _to_user(self, out: np.ndarray) -> np.ndarray:
        """Solved vertices -> the user's (each copy of a welded vertex, then a cut's copies)."""
        if self._copies is None:
            return out
        keep = out[:, self._copies]
        if self._appended:
            keep = np.concatenate([keep, out[:, self.target.n_vertices - self._appended:]], axis=1)
        return keep


def _longest(d: np.ndarray) -> float:
    """The longest of the vectors d (..., 3) (np.linalg.norm over an axis of 3 is 17x slower:
    6.8 against 0.4 ms on 16 frames)."""
    d = d * d
    return float(np.sqrt((d[..., 0] + d[..., 1] + d[..., 2]).max())) if d.size else 0.0


def _eye_template(source, source_landmarks):
    """The source's eyes as templates for a target's sealed ones: its skin, and its eyes where
    it has them as parts (correspond.parts)."""
    from ..correspond.eyes import eye_template
    from ..correspond.parts import EYE_LEFT, EYE_RIGHT, ROLES, split_parts
    ls = source_landmarks.positions(source)
    ps = split_parts(source, ls)
    eyes = {side: ps.role == ROLES.index(role) for side, role in (("left", EYE_LEFT), ("right", EYE_RIGHT))}
    return eye_template(source, ls, ps.skin, {side: on for side, on in eyes.items() if on.any()})


def _off_the_eyes(ec, points) -> Landmarks:
    """The landmarks on the cut mesh, those of the lids (36-47) on the lids' faces, not the eyes'."""
    lm = Landmarks.snap(ec.mesh, points)
    inside = np.zeros(ec.mesh.n_vertices, bool)
    for v in ec.eyes.values():
        inside[v] = True
    tri = ec.mesh.triangles
    on_eye = inside[tri].all(1)
    lids = np.arange(36, 48)
    bad = lids[on_eye[lm.triangle[lids]]]
    if len(bad):
        keep = np.nonzero(~on_eye)[0]
        sub = Mesh.from_faces(ec.mesh.vertices, tri[keep])
        snapped = Landmarks.snap(sub, points[bad])
        lm.triangle[bad], lm.bary[bad] = keep[snapped.triangle], snapped.bary
    return lm


def _user_cut(user: Mesh, welded: Mesh, mc) -> Mesh:
    """The user's mesh with the mouth cut: its vertices in their order, the cut's copies after
    them, the faces below the seam on the copies."""
    if user is welded:
        return mc.mesh
    n_w, n_u = welded.n_vertices, user.n_vertices
    fi = mc.mesh.face_indices
    new = np.where(fi >= n_w, n_u + fi - n_w, user.face_indices)
    v = np.vstack([user.vertices, mc.mesh.vertices[n_w:]])
    return Mesh(v, new, user.face_starts, user.uv, user.face_uv_indices, user.name, user.groups, user.group_names,
                user.layout)
