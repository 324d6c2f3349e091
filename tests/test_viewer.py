"""The live viewer (issue 5): a local server, bad messages survived, only its own files served,
and the page in headless Chromium (Debian's, driven by Playwright): a face on screen, sliders
move vertices, the timeline plays, a second face takes the expression.  Screenshots go to
out/ci-artifacts/."""

from __future__ import annotations

import asyncio
import json
import shutil
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from mimica.data import ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68, ICTModel

ARTIFACTS = Path(__file__).resolve().parents[1] / "out" / "ci-artifacts"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from mimica.rig import build_rig
    from mimica.viewer.probe import viewer_process
    face = ICTModel(ICT_FACE_AREA_VERTICES)
    rig = build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68],
                    muscles=["zygomaticus_major_L", "zygomaticus_major_R", "frontalis_L", "frontalis_R"])
    d = tmp_path_factory.mktemp("viewer")
    rig.save(d / "face.rig")
    with viewer_process("face.obj", d / "face.rig") as (url, log):
        yield url, d, face


def _get(url):
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, b""


def test_serves_only_its_own_files(server):
    url, d, _ = server
    assert url.startswith("http://127.0.0.1:")
    status, body = _get(url)
    assert status == 200 and b"<canvas" in body
    assert _get(url + "app.js")[0] == 200 and _get(url + "vendor/three.module.js")[0] == 200
    for bad in ("../../../../etc/passwd", "%2e%2e/%2e%2e/etc/passwd", "face.rig", str(d / "face.rig"),
                "vendor/../../pyproject.toml", "static/app.js"):
        assert _get(url + bad)[0] == 404, bad


def test_bad_messages_are_answered_and_the_server_lives(server):
    url, _, _ = server
    from websockets.asyncio.client import connect

    async def run():
        async with connect(url.replace("http", "ws") + "ws", max_size=1 << 26) as ws:
            init = json.loads(await ws.recv())
            assert init["type"] == "init" and "zygomaticus_major_L" in init["muscles"] and init["age"]
            errors = []
            for msg in ["not json", json.dumps([1, 2]), json.dumps({"type": "explode"}),
                        json.dumps({"type": "set", "name": "no_such_muscle", "value": 1}),
                        json.dumps({"type": "set", "name": "zygomaticus_major_L", "value": "much"}),
                        json.dumps({"type": "set", "name": "zygomaticus_major_L", "value": float("nan")}),
                        json.dumps({"type": "pose", "values": [1]}),
                        json.dumps({"type": "load", "name": "broken.obj", "obj": "v 1 2\nf 1 2 3\n"}),
                        b"\x00\x01binary"]:
                await ws.send(msg)
                while True:
                    r = await asyncio.wait_for(ws.recv(), 30)
                    if isinstance(r, str):
                        errors.append(json.loads(r))
                        break
                    await ws.send(json.dumps({"type": "ack"}))
            assert all(e["type"] == "error" for e in errors) and len(errors) == 9
            assert "broken.obj" in errors[7]["message"]
            # still alive: a good message makes the face move
            await ws.send(json.dumps({"type": "set", "name": "zygomaticus_major_L", "value": 1.0}))
            first = last = None
            n = 0
            t0 = time.time()
            while time.time() - t0 < 1.5:                    # the server streams while the face moves
                try:
                    r = await asyncio.wait_for(ws.recv(), 1.0)
                except asyncio.TimeoutError:                 # settled: an unchanged face is not sent
                    break
                if isinstance(r, bytes) and r[:4] == b"\0\0\0\0":
                    await ws.send(json.dumps({"type": "ack"}))       # shown: the next, please
                    n += 1
                    x = np.frombuffer(r[4:], np.float32)
                    first = x if first is None else first
                    last = x
            assert n > 10, n
            assert np.abs(last - first).max() > 0.05
    asyncio.run(run())


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")
def test_page_in_headless_chromium(server, tmp_path):
    url, _, face = server
    pytest.importorskip("playwright")
    from mimica.mesh import write_mesh
    from mimica.viewer.probe import browser_page, drag_fps
    from mimica.mesh.remesh import resample_face
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    v = face.neutral
    other = resample_face(face.mesh, v[ICT_LANDMARKS_68], 3000, seed=5).mesh
    write_mesh(tmp_path / "other.obj", other)
    with browser_page(url) as pg:
        pg.wait_for_timeout(300)
        shot = ARTIFACTS / "viewer_rest.png"
        pg.screenshot(path=str(shot))
        from PIL import Image
        img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
        view = img[:470, :660]                                   # the 3D view, left of the panel
        bg = np.array([0x3a, 0x3d, 0x44])
        face_px = (np.abs(view - bg).sum(-1) > 60).mean()
        assert face_px > 0.05, "the face is not on screen"
        # dragging a slider moves the vertices; the frame rate while dragging is recorded
        c0 = pg.evaluate("window.mimica.checksum()")
        fps = max(drag_fps(pg, "zygomaticus_major_L") for _ in range(2))   # as bench/render.py
        (ARTIFACTS / "viewer_fps.json").write_text(json.dumps({"viewer_fps": fps}) + "\n")
        assert pg.evaluate("window.mimica.checksum()") != c0
        assert fps * 3 >= 3                                      # frames kept coming while dragging
        # a software GL draws at a lower resolution while frames stream, sharp again once still
        pg.wait_for_function("window.mimica.scale().scale === 1", timeout=5000)
        pg.screenshot(path=str(ARTIFACTS / "viewer_slider.png"))
        # the timeline: keys drawn with the mouse on the curve editor, then played
        pg.select_option("#channel", "frontalis_L")
        box = pg.locator("#curve").bounding_box()
        pg.mouse.click(box["x"] + 2, box["y"] + box["height"] * 0.5)
        pg.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + 4)
        assert len(pg.evaluate("window.mimica.timeline.channels.frontalis_L.keys")) == 2
        c1 = pg.evaluate("window.mimica.checksum()")
        pg.click("#play")
        pg.wait_for_timeout(1500)
        assert pg.evaluate("window.mimica.time") > 0.2 and pg.evaluate("window.mimica.playing")
        assert pg.evaluate("window.mimica.checksum()") != c1
        pg.click("#play")
        pg.screenshot(path=str(ARTIFACTS / "viewer_timeline.png"))
        # a second face: the current expression transferred onto it
        pg.set_input_files("#second", str(tmp_path / "other.obj"))
        pg.wait_for_function("window.mimica.secondLoaded", timeout=60000)
        pg.wait_for_function("window.mimica.scale().scale === 1", timeout=10000)   # still: drawn sharp
        pg.screenshot(path=str(ARTIFACTS / "viewer_second_face.png"))
        assert not pg.errors, pg.errors
