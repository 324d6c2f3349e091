"""Driving videos: frames from an MP4 (ffmpeg via imageio) or a folder of images; MP4 out."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from .io import read_image, to_uint8

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tif", ".tiff", ".webp")


def _ffmpeg():
    from .._extras import require
    return require("imageio_ffmpeg", "photo", "video (or a folder of frames instead)")


def frame_source(path, raw: bool = False):
    """A video's (or a folder of images') frames, read as they are used.

    Parameters
    ----------
    path : str or Path
        A video file (imageio-ffmpeg) or a folder of images (in name order).
    raw : bool
        The frames as uint8, as a video holds them (their conversion to float costs 2.5 ms a
        640x480 frame, more than its decoding).

    Returns
    -------
    count : int or None
        The frames, where known.
    fps : float
    frames : iterator of (h, w, 3) float arrays
        RGB in [0, 1] (`raw`: uint8).
    """
    path = Path(path)
    if path.is_dir():
        files = sorted(f for f in path.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise MimicaError(f"{path}: the folder holds no image frames ({', '.join(IMAGE_SUFFIXES)})")
        return len(files), 25.0, ((to_uint8(read_image(f)) if raw else read_image(f)) for f in files)
    if not path.is_file():
        raise MimicaError(f"{path}: no such video or folder")
    ff = _ffmpeg()
    try:
        reader = ff.read_frames(str(path))
        meta = next(reader)
    except (RuntimeError, OSError, StopIteration) as e:
        raise MimicaError(f"{path}: not a video ffmpeg can read, or cut short before its index "
                          f"({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    w, h = meta["size"]
    fps = float(meta.get("fps") or 25.0)
    n = int(round(meta.get("duration", 0) * fps)) or None

    def gen():
        for buf in reader:
            frame = np.frombuffer(buf, np.uint8).reshape(h, w, 3)
            yield frame if raw else frame.astype(np.float32) / 255.0
    return n, fps, gen()


class VideoWriter:
    """H.264 MP4 through imageio-ffmpeg; written to a temporary file, moved into place on close.

    Parameters
    ----------
    path : str or Path
    fps : float
    """

    def __init__(self, path, fps=25.0):
        import os
        import tempfile
        from ..outputs import make_parent, os_error
        self.path = Path(path)
        make_parent(self.path)
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.stem}.", suffix=".mp4", dir=self.path.parent)
        except OSError as e:
            raise os_error(self.path, e) from None
        os.close(fd)
        self.tmp, self.fps, self.gen, self.n = Path(tmp), fps, None, 0

    def write(self, img):
        frame = to_uint8(img)
        h, w = frame.shape[:2]
        if self.gen is None:
            ff = _ffmpeg()
            self.gen = ff.write_frames(str(self.tmp), (w - w % 2, h - h % 2), fps=self.fps, quality=7,
                                       macro_block_size=2, pix_fmt_out="yuv420p", ffmpeg_log_level="error")
            self.gen.send(None)
        self.gen.send(np.ascontiguousarray(frame[:h - h % 2, :w - w % 2]))
        self.n += 1

    def close(self, ok=True):
        import os
        from ..outputs import file_mode, os_error
        try:
            if self.gen is not None:
                self.gen.close()
            if ok and self.n:
                os.chmod(self.tmp, file_mode())      # mkstemp made it 0600
                os.replace(self.tmp, self.path)
        except OSError as e:
            raise os_error(self.path, e) from None
        finally:
            if self.tmp.exists():
                self.tmp.unlink()

    def __enter__(self):
        return self

    def __exit__(self, et, ev, tb):
        self.close(ok=et is None)
        return False
