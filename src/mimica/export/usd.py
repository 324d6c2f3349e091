"""USD: a head with named blend shapes and, for a clip, a SkelAnimation of
their weights (UsdSkel, through Pixar's usd-core: `pip install mimica[usd]`).

Layout: /Head (SkelRoot) > Skel (Skeleton, one root joint at identity, as UsdSkel wants a
skeleton to carry an animation) > Anim (SkelAnimation: blendShapes, blendShapeWeights per
time code); /Head/Mesh (Mesh bound to Skel; skel:blendShapes and one BlendShape child per
shape, its offsets stored only where the vertex moves, pointIndices).  The stage is y-up, with
metersPerUnit from the mesh's unit (ICT-FaceKit: 0.01), timeCodesPerSecond the clip's rate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..mesh import Mesh
from ..mesh.io import SPARSE_TOLERANCE, glb_units

USD_SUFFIXES = (".usd", ".usda", ".usdc")


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt
    except ImportError:
        raise MimicaError("USD files need Pixar's usd-core: pip install 'mimica[usd]'") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt


def write_usd(path, mesh: Mesh, shapes: dict, weights=None, fps: float | None = None, units: str = "auto",
              tolerance: float = SPARSE_TOLERANCE) -> dict:
    """Write a mesh with blend shapes as USD (usd-core), whole or not at all.

    Parameters
    ----------
    path : str or Path
        .usd, .usda or .usdc.
    mesh : Mesh
    shapes : dict
        {name: (n, 3) positions}.
    weights : (F, len(shapes)) float array or None
        With fps: an animation (a SkelAnimation of the blend shapes' weights).
    fps : float or None
    units : str
        The mesh's unit ("auto": glb_units); the stage's metersPerUnit says it.
    tolerance : float
        Metres below which a vertex's offset is left out of its blend shape.

    Returns
    -------
    dict
        {"units": the unit used, "shapes": how many blend shapes}.
    """
    import os
    path = Path(path)
    if path.suffix.lower() not in USD_SUFFIXES:
        raise MimicaError(f"{path}: a USD file ends in {', '.join(USD_SUFFIXES)}")
    _pxr()
    from ..outputs import make_parent
    make_parent(path)
    tmp = path.with_name(f".{path.stem}.part{path.suffix}")
    try:
        info = _write(tmp, mesh, shapes, weights, fps, units, tolerance)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return info


def _write(path, mesh, shapes, weights, fps, units, tolerance) -> dict:
    Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
    unit, k = glb_units(mesh, units)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, k)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdSkel.Root.Define(stage, "/Head")
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, "/Head/Skel")
    skel.CreateJointsAttr(["root"])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    m = UsdGeom.Mesh.Define(stage, "/Head/Mesh")
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.vertices.astype(np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(mesh.face_sizes.astype(np.int32)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.face_indices.astype(np.int32)))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    m.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    if mesh.uv is not None and mesh.face_uv_indices is not None:
        st = UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromNumpy(mesh.uv.astype(np.float32)))
        st.SetIndices(Vt.IntArray.FromNumpy(mesh.face_uv_indices.astype(np.int32)))
    bind = UsdSkel.BindingAPI.Apply(m.GetPrim())
    bind.CreateSkeletonRel().SetTargets([skel.GetPath()])
    bind.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    bind.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    bind.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    names, targets = [], []
    for name, pos in shapes.items():
        token = Tf.MakeValidIdentifier(str(name))
        d = np.asarray(pos, float) - mesh.vertices
        keep = np.nonzero(np.linalg.norm(d, axis=1) * k > tolerance)[0]
        if not len(keep):
            keep = np.array([0])
        bs = UsdSkel.BlendShape.Define(stage, m.GetPath().AppendChild(token))
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(d[keep].astype(np.float32)))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(keep.astype(np.int32)))
        names.append(token)
        targets.append(bs.GetPath())
    bind.CreateBlendShapesAttr(names)
    bind.CreateBlendShapeTargetsRel().SetTargets(targets)
    if weights is not None and fps:
        w = np.asarray(weights, np.float32)
        if w.ndim != 2 or w.shape[1] != len(names):
            raise MimicaError(f"weights: {w.shape} for {len(names)} blend shapes")
        anim = UsdSkel.Animation.Define(stage, "/Head/Skel/Anim")
        anim.CreateJointsAttr(["root"])
        anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0)]))
        anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1)]))
        anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1)]))
        anim.CreateBlendShapesAttr(names)
        attr = anim.CreateBlendShapeWeightsAttr()
        for f, row in enumerate(w):
            attr.Set(Vt.FloatArray.FromNumpy(row), Usd.TimeCode(f))
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        stage.SetTimeCodesPerSecond(float(fps))
        stage.SetFramesPerSecond(float(fps))
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(len(w) - 1)
    stage.GetRootLayer().Save()
    return {"units": unit, "shapes": len(names)}
