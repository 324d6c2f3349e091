"""Drive the viewer page in a headless Chromium (Playwright + the system's Chromium): the timing
harness of the browser tests and of bench/render.py (kept out of the package: not a user tool)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import threading
import time
from contextlib import contextmanager

# WebGL on SwiftShader, the page composited in software (what Chromium does without a GPU;
# compositing through SwiftShader as well cost a third of the frame rate, measured)
SOFTWARE_GL = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu-compositing", "--no-sandbox"]


def chromium_path():
    return shutil.which("chromium") or shutil.which("chromium-browser")


@contextmanager
def viewer_process(face, rig, extra=(), timeout=180):
    """`mimica view FACE --rig RIG --no-browser` in its own process (rig None: no --rig, the face
    rigged by the command); yields (url, log lines).  The child runs the same mimica as this
    process (a checkout's src/ or the installed one) with the same data directory."""
    import os
    from pathlib import Path
    import mimica
    from mimica.data import data_dir
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(mimica.__file__).resolve().parents[1])] + os.environ.get("PYTHONPATH", "").split(os.pathsep)))
    if data_dir() is not None:
        env["MIMICA_DATA"] = str(data_dir())
    rig_args = [] if rig is None else ["--rig", str(rig)]
    proc = subprocess.Popen([sys.executable, "-m", "mimica.cli", "view", str(face), *rig_args, "--no-browser", *extra],
                            stderr=subprocess.PIPE, text=True, env=env)
    url, log, t0 = None, [], time.time()
    for line in proc.stderr:
        log.append(line)
        m = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[\w-]+)", line)
        if m:
            url = m.group(1)
            break
        if time.time() - t0 > timeout:
            break
    if url is None:
        proc.kill()
        raise RuntimeError("the viewer did not start: " + "".join(log))
    threading.Thread(target=lambda: log.extend(proc.stderr), daemon=True).start()   # never let the pipe fill
    try:
        yield url, log
    finally:
        proc.terminate()
        proc.wait(10)


def ws_url(url: str, token: str | None = None) -> str:
    """The WebSocket address of a viewer whose page is `url` (http://host:port/?token=T);
    `token` replaces the page's (for refusal tests)."""
    base, tok = url.split("?token=")
    return base.replace("http", "ws", 1) + "ws?token=" + (tok if token is None else token)


@contextmanager
def browser_page(url, size=(960, 640), query="software"):
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium_path(), args=SOFTWARE_GL)
        try:
            pg = b.new_page(viewport={"width": size[0], "height": size[1]})
            pg.errors = []
            pg.on("pageerror", lambda e: pg.errors.append(str(e)))
            pg.goto(url + ("&" if "?" in url else "?") + query)
            pg.wait_for_function("window.mimica && window.mimica.ready && window.mimica.framesApplied > 0",
                                 timeout=30000)
            yield pg
        finally:
            b.close()


def drag_fps(pg, slider: str, seconds: float = 3.0) -> float:
    """Frames the page shows per second while a slider is moved every 16 ms (like a drag)."""
    pg.evaluate("""(name) => { const i = document.querySelector(`input[data-name="${name}"]`); let n = 0;
        window.__drag = setInterval(() => { i.value = 0.5 + 0.5 * Math.sin(n++ / 5);
                                             i.dispatchEvent(new Event('input')); }, 16); }""", slider)
    f0, t0 = pg.evaluate("window.mimica.framesApplied"), time.time()
    pg.wait_for_timeout(int(seconds * 1000))
    fps = (pg.evaluate("window.mimica.framesApplied") - f0) / (time.time() - t0)
    pg.evaluate("clearInterval(window.__drag)")
    return fps
