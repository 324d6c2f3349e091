"""ARKit shapes on a head nobody here made

The shared real head (MediaPipe's canonical face: 468 vertices, another topology, its lips and
eyes sealed, no landmark file) gets the 52 ARKit blendshapes in one call of the pipeline, as
`mimica blendshapes head.obj --out head.glb` makes them; seven drawn from the front.  Its lips
are cut apart along their seam first, so `jawOpen` opens a mouth.
"""
import os
import sys
import tempfile
from pathlib import Path

from mimica.image import write_image
from mimica.pipeline import make_blendshapes
from mimica.render import contact_sheet, render_views

head = Path(os.environ.get("MIMICA_DATA", "../shared/data")) / "real-heads" / "mediapipe-canonical"
with tempfile.TemporaryDirectory() as d:
    r = make_blendshapes(head / "head.obj", Path(d) / "head.glb")     # its landmarks found on renders
names = ["jawOpen", "mouthSmileLeft", "mouthFunnel", "browInnerUp", "mouthStretchRight", "cheekPuff", "jawLeft"]
mesh = r.shapes.mesh
tiles = [render_views(mesh, None if n == "rest" else r.shapes[n], views=("front",), size=300)[0]
         for n in ["rest"] + names]
write_image(sys.argv[1], contact_sheet(tiles, ["rest"] + names, columns=4))
