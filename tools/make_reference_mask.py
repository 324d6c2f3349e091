"""Regenerate the shipped reference wrinkle mask (src/mimica/wrinkles/reference.wrinkles)
on the ICT-FaceKit generic neutral face from its landmarks (mimica.wrinkles.mask).

Run from the project root: .venv/bin/python tools/make_reference_mask.py
"""

from pathlib import Path

from mimica.data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel
from mimica.wrinkles.mask import define_reference

if __name__ == "__main__":
    mesh = ICTModel(ICT_HEAD_VERTICES).mesh
    mask = define_reference(mesh, mesh.vertices[ICT_LANDMARKS_68], face="ict-facekit generic neutral")
    out = Path(__file__).resolve().parents[1] / "src/mimica/wrinkles/reference.wrinkles"
    mask.save(out)
    print(f"{len(mask)} wrinkles -> {out}")
