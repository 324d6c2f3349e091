"""Benchmark: pictures and take-home files.

- render_s: a 26,719-vertex head (the whole ICT-FaceKit model) to a 1024x1024 PNG, render and
  PNG encoding, best of 3; beside it the same render drawing every triangle (no back-face
  culling), the baseline.
- mp4: 120 turntable frames at 512x512 to H.264.
- blendshapes_s: the 52 ARKit shapes onto a 22,708-vertex head of another topology (ICT
  identity011 resampled with its own triangulation), from the command line's function,
  landmarks found automatically, with the ICT shapes' cache warm (cold printed too).
- viewer_fps: `mimica view` (its own process, Kim's 8 muscles on the ICT face area, wrinkles on)
  in headless Chromium (Debian's, software GL: SwiftShader) driven by Playwright: frames the
  page shows per second while a muscle slider moves every 16 ms; beside it, the frames per
  second the server streams to a plain WebSocket client (no drawing), the baseline.

Run from the project root: .venv/bin/python bench/render.py
Picture: docs/figures/blendshapes.png (ARKit shapes on the resampled head).
"""

from __future__ import annotations

import io
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "tools"))  # viewer_probe: the browser harness

from mimica.data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel  # noqa: E402
from mimica.export import arkit_blendshapes  # noqa: E402
from mimica.store import TemplateStore  # noqa: E402
from mimica.image.video import VideoWriter  # noqa: E402
from mimica.correspond.remesh import resample_face  # noqa: E402
from mimica.render import contact_sheet, face_framing, render_mesh, save_png, turntable_angles  # noqa: E402
from mimica.render.shots import shared_frame_all_views  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()                   # as the command line does (mimica/_memory.py)

FIG = ROOT / "docs" / "figures"


def best(f, n=3):
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        t.append(time.perf_counter() - t0)
    return min(t)


def render_png(mesh, cull=None):
    img = render_mesh(mesh, size=(1024, 1024), cull=cull)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG", compress_level=3)


def main():
    print(f"machine: {platform.machine()}, python {platform.python_version()}")
    full = ICTModel()
    mesh = full.mesh
    render_png(mesh)
    t_cull = best(lambda: render_png(mesh))
    t_all = best(lambda: render_png(mesh, cull=False))
    print(f"1024x1024 PNG of the {mesh.n_vertices}-vertex head: {t_cull:.3f}s (back faces culled), "
          f"{t_all:.3f}s drawing every triangle")

    frame = shared_frame_all_views(mesh.vertices, [(y, 0.0) for y in turntable_angles(8)])
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with VideoWriter(Path(tmp) / "turn.mp4", 30) as vw:
            for y in turntable_angles(120):
                vw.write(render_mesh(mesh, size=(512, 512), yaw=y, frame=frame) / 255.0)
        t_mp4 = time.perf_counter() - t0
    print(f"turntable MP4, 120 frames 512x512: {t_mp4:.1f}s")

    head = ICTModel(ICT_HEAD_VERTICES)
    v = head.identity("identity011")
    target = resample_face(head.mesh.with_vertices(v), v[ICT_LANDMARKS_68], 20000, seed=7).mesh
    with tempfile.TemporaryDirectory() as cache:
        store = TemplateStore(cache=cache)
        t0 = time.perf_counter()
        shapes = arkit_blendshapes(target, store=store)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        shapes = arkit_blendshapes(target, store=store)
        warm = time.perf_counter() - t0
    print(f"52 ARKit blendshapes on a {target.n_vertices}-vertex head of another topology: {warm:.2f}s "
          f"({cold:.2f}s with the ICT shapes read from OBJ the first time)")
    show = ["jawOpen", "mouthSmileLeft", "eyeBlinkRight", "browInnerUp", "mouthPucker", "noseSneerLeft"]
    fr = face_framing(v[ICT_LANDMARKS_68])
    tiles = [render_mesh(target, size=(300, 300), frame=fr)] + \
        [render_mesh(target, shapes[n], size=(300, 300), frame=fr) for n in show]
    FIG.mkdir(parents=True, exist_ok=True)
    save_png(FIG / "blendshapes.png", contact_sheet(tiles, labels=["rest"] + show, columns=4,
                                                    title=f"ARKit blendshapes on a {target.n_vertices}-vertex head "
                                                          "of another topology (mimica blendshapes)"))
    vfps = viewer()
    print(f"render_s={t_cull:.3f} blendshapes_s={warm:.2f} viewer_fps={vfps:.1f}")


def viewer():
    import asyncio
    import json
    from mimica.data import ICT_FACE_AREA_VERTICES
    from mimica.physics import precompute
    from mimica.rig import build_rig
    from viewer_probe import browser_page, chromium_path, drag_fps, viewer_process, ws_url
    from websockets.asyncio.client import connect
    if chromium_path() is None:
        print("viewer: no Chromium on this machine (apt install chromium)")
        return float("nan")
    face = ICTModel(ICT_FACE_AREA_VERTICES)
    rig = precompute(build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68]))   # as `mimica rig` saves it
    with tempfile.TemporaryDirectory() as tmp:
        rig.save(Path(tmp) / "face.rig")
        with viewer_process("face.obj", Path(tmp) / "face.rig") as (url, _):
            async def socket_fps():
                async with connect(ws_url(url), max_size=1 << 26) as ws:
                    n, t0, k = 0, time.time(), 0
                    while time.time() - t0 < 2.5:
                        await ws.send(json.dumps({"type": "set", "name": "zygomaticus_major_L",
                                                  "value": 0.5 + 0.4 * np.sin(k / 5)}))
                        k += 1
                        try:
                            while True:
                                r = await asyncio.wait_for(ws.recv(), 0.016)
                                if isinstance(r, bytes) and r[:4] == b"\0\0\0\0":
                                    n += 1
                                    await ws.send(json.dumps({"type": "ack"}))
                        except asyncio.TimeoutError:
                            pass
                    return n / (time.time() - t0)
            base = asyncio.run(socket_fps())
            with browser_page(url) as pg:
                fps = max(drag_fps(pg, "zygomaticus_major_L") for _ in range(2))
    print(f"viewer: {fps:.1f} frames/s shown in headless Chromium (software GL) while a slider is dragged; "
          f"the server streams {base:.1f} frames/s to a WebSocket client that does not draw")
    return fps


if __name__ == "__main__":
    main()
