"""meshopt-compressed glTF buffer views (EXT_meshopt_compression, as gltfpack writes them),
decoded so that the rest of the glTF reader and writer see plain buffer views.

Each compressed view names its compressed bytes in the extension; its own `buffer` is often a
placeholder with no data (a "fallback" buffer).  The bytes are decoded by the extension's
bitstream specification (Appendix A: attributes, triangles, indices; Appendix B: the
octahedral, quaternion and exponential filters), written here because no well-kept Python
decoder exists (meshoptimizer's own is C++ and WebAssembly; PyPI's bindings are an alpha
source package).  The decoded bytes are appended to the file's one buffer, the view pointed at
them and its extension dropped (and the file's, once no view uses it); data that stays quantized
keeps KHR_mesh_quantization.  A file written back is then uncompressed, all else as it was.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import MimicaError
from .gltf_spec import drop_extension

EXTENSION = "EXT_meshopt_compression"
_SHIFT2 = (6, 4, 2, 0)            # 2-bit deltas, the first in the byte's top bits
_SHIFT4 = (4, 0)


def placeholder(doc: dict, i: int) -> bool:
    """Whether buffer `i` holds no data of its own: a meshopt fallback, or a buffer without a uri
    that only compressed views use and no compressed data is read from (a GLB's own chunk is)."""
    b = doc["buffers"][i]
    if (b.get("extensions") or {}).get(EXTENSION, {}).get("fallback"):
        return True
    views = [v for v in doc.get("bufferViews") or [] if v.get("buffer") == i]
    squeezed = [(v.get("extensions") or {}).get(EXTENSION) for v in views]
    sources = {(v.get("extensions") or {}).get(EXTENSION, {}).get("buffer") for v in doc.get("bufferViews") or []}
    return b.get("uri") is None and bool(views) and all(squeezed) and i not in sources


def decode_meshopt(doc: dict, buf, path: Path) -> int:
    """Decode every meshopt-compressed buffer view of a glTF document in place.

    Parameters
    ----------
    doc : dict
        The glTF JSON, its buffers merged into `buf` (buffer 0; each extension's byteOffset into it).
    buf : gltf._Buffers
        Its bytes; the decoded views are appended.
    path : Path
        The file (for messages).

    Returns
    -------
    int
        How many buffer views were decoded.
    """
    n = 0
    for i, v in enumerate(doc.get("bufferViews") or []):
        ext = (v.get("extensions") or {}).get(EXTENSION)
        if ext is None:
            continue
        where = f"{path}: buffer view {i}"
        try:
            count, stride, mode = int(ext["count"]), int(ext["byteStride"]), ext["mode"]
            start, length = int(ext.get("byteOffset", 0)), int(ext["byteLength"])
        except (KeyError, TypeError, ValueError):
            raise MimicaError(f"{where}: its meshopt compression lacks its count, byteStride, mode or byteLength "
                              "(not valid glTF)") from None
        data = bytes(buf.data[start:start + length])
        if len(data) != length:
            raise MimicaError(f"{where}: its compressed bytes run past the end of its buffer (the file is cut short?)")
        try:
            if mode == "ATTRIBUTES":
                raw = _filtered(_attributes(data, count, stride), ext.get("filter", "NONE"), stride)
            elif mode == "TRIANGLES":
                raw = _triangles(data, count, stride)
            elif mode == "INDICES":
                raw = _indices(data, count, stride)
            else:
                raise ValueError(f"unknown mode {mode!r}")
        except (ValueError, IndexError) as e:
            raise MimicaError(f"{where}: its meshopt-compressed data does not decode ({e})") from None
        out = raw.tobytes()
        if len(out) != v.get("byteLength", len(out)):
            raise MimicaError(f"{where}: it decodes to {len(out)} bytes where the view says {v.get('byteLength')}")
        v["buffer"], v["byteOffset"] = 0, buf.append(out)
        del v["extensions"][EXTENSION]
        if not v["extensions"]:
            del v["extensions"]
        n += 1
    if n:
        for b in doc.get("buffers") or []:
            (b.get("extensions") or {}).pop(EXTENSION, None)
        drop_extension(doc, EXTENSION)
    return n


def _zigzag8(d: np.ndarray) -> np.ndarray:
    """Appendix A's byte zigzag: (v & 1) ? ~(v >> 1) : (v >> 1), in 8 bits."""
    return np.where(d & 1, ~(d >> 1), d >> 1).astype(np.uint8)


def _attributes(data: bytes, count: int, stride: int) -> np.ndarray:
    """Mode 0 (Appendix A): (count, stride) bytes, each byte column's deltas from the element
    before (the first from the baseline element at the stream's end), in groups of 16."""
    if not data or data[0] != 0xA0:
        raise ValueError(f"attribute stream header {data[:1].hex() or 'missing'}, not a0")
    if stride % 4 or not 0 < stride <= 256:
        raise ValueError(f"byteStride {stride}")
    tail = max(32, stride)
    if len(data) < 1 + tail:
        raise ValueError("the stream is shorter than its tail")
    end = len(data) - tail
    base = np.frombuffer(data, np.uint8, stride, len(data) - stride)        # padding first, then the element
    block = min((8192 // stride) & ~15, 256)
    deltas = np.zeros((count, stride), np.uint8)
    pos, done = 1, 0
    while done < count:
        n = min(count - done, block)
        groups = (n + 15) // 16
        head = (groups + 3) // 4
        for k in range(stride):
            if pos + head > end:
                raise ValueError("the stream ends inside a block")
            modes = [(data[pos + g // 4] >> (2 * (g % 4))) & 3 for g in range(groups)]
            pos += head
            col = bytearray(groups * 16)
            for g, m in enumerate(modes):
                at = g * 16
                if m == 3:
                    col[at:at + 16] = data[pos:pos + 16]
                    pos += 16
                elif m:
                    bits, width = (2, 4) if m == 1 else (4, 8)
                    shifts, top = (_SHIFT2, 3) if m == 1 else (_SHIFT4, 15)
                    vals = [(data[pos + j] >> s) & top for j in range(width) for s in shifts]
                    pos += width
                    for j, x in enumerate(vals):
                        if x == top:                   # the sentinel: the delta is the next byte
                            x = data[pos]
                            pos += 1
                        col[at + j] = x
            if pos > end:
                raise ValueError("the stream ends inside a block")
            deltas[done:done + n, k] = np.frombuffer(bytes(col), np.uint8)[:n]
        done += n
    if pos != end:
        raise ValueError(f"{end - pos} bytes left over before the tail")
    return (base[None] + np.cumsum(_zigzag8(deltas), axis=0, dtype=np.uint8)).astype(np.uint8)


def _filtered(raw: np.ndarray, flt: str, stride: int) -> np.ndarray:
    """Appendix B's filter on decoded elements ((count, stride) bytes); the result's bytes."""
    if flt in (None, "NONE"):
        return raw
    if flt == "OCTAHEDRAL":                      # unit vectors, 8- or 16-bit, the third component 1.0
        if stride not in (4, 8):
            raise ValueError(f"octahedral filter on byteStride {stride}")
        t = np.int8 if stride == 4 else np.int16
        v = raw.view(t).reshape(-1, 4).astype(np.float32)
        one = np.where(v[:, 2] == 0, 1.0, v[:, 2])
        x, y = v[:, 0] / one, v[:, 1] / one
        z = 1.0 - np.abs(x) - np.abs(y)
        neg = np.minimum(z, 0.0)
        x, y = x - np.copysign(neg, x), y - np.copysign(neg, y)
        length = np.sqrt(x * x + y * y + z * z)
        length[length == 0] = 1.0
        top = float(np.iinfo(t).max)
        out = np.stack([np.rint(x / length * top), np.rint(y / length * top), np.rint(z / length * top), v[:, 3]], 1)
        return out.astype(t)
    if flt == "QUATERNION":                      # unit quaternions, the largest component left out
        if stride != 8:
            raise ValueError(f"quaternion filter on byteStride {stride}")
        v = raw.view(np.int16).reshape(-1, 4)
        one = (v[:, 3].astype(np.int32) | 3).astype(np.float32)
        xyz = v[:, :3].astype(np.float32) / one[:, None] * np.float32(1 / np.sqrt(2))
        w = np.sqrt(np.maximum(0.0, 1.0 - (xyz ** 2).sum(1)))
        big = (v[:, 3] & 3).astype(np.int64)
        out = np.zeros((len(v), 4), np.float32)
        rows = np.arange(len(v))
        for j in range(3):
            out[rows, (big + 1 + j) % 4] = xyz[:, j]
        out[rows, big] = w
        return np.rint(out * 32767.0).astype(np.int16)
    if flt == "EXPONENTIAL":                     # 2^e * m: an 8-bit exponent over a 24-bit mantissa
        if stride % 4:
            raise ValueError(f"exponential filter on byteStride {stride}")
        v = raw.view("<i4").reshape(-1)
        e = (v >> 24).astype(np.float64)
        m = ((v << 8) >> 8).astype(np.float64)
        return (np.exp2(e) * m).astype("<f4")
    raise ValueError(f"unknown filter {flt!r}")


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    """An unsigned LEB128 value at data[pos]: (value, position after it)."""
    v = shift = 0
    while True:
        b = data[pos]
        pos += 1
        v |= (b & 0x7F) << shift
        if b < 0x80:
            return v, pos
        shift += 7


def _triangles(data: bytes, count: int, stride: int) -> np.ndarray:
    """Mode 1 (Appendix A): a triangle list's indices from its codes, the edge and vertex FIFOs,
    explicit indices as deltas from `last`, and the 16-byte codeaux table at the end."""
    if not data or data[0] != 0xE1:
        raise ValueError(f"triangle stream header {data[:1].hex() or 'missing'}, not e1")
    if count % 3 or stride not in (2, 4):
        raise ValueError(f"triangles: count {count}, byteStride {stride}")
    tris = count // 3
    if len(data) < 1 + tris + 16:
        raise ValueError("the stream is shorter than its codes and table")
    aux = data[len(data) - 16:]
    codes, pos, end = 1, 1 + tris, len(data) - 16
    out = np.zeros(count, np.int64)
    edges = [(0, 0)] * 16                       # most recent first
    verts = [0] * 16
    nxt = last = 0

    def index(p):
        nonlocal last
        v, p = _varint(data, p)
        last = (last + ((~(v >> 1)) if v & 1 else (v >> 1))) & 0xFFFFFFFF
        return last, p

    def other(nib, explicit, pushed):
        """b or c of a 0xfY / 0xfe / 0xff code from its nibble: `next` (pushed), the vertex FIFO
        at nib - 1, or (0xf, for 0xfe / 0xff) an explicit index (pushed)."""
        nonlocal nxt, pos
        if nib == 0:
            v = nxt
            nxt += 1
        elif nib < 15 or not explicit:
            return verts[nib - 1]
        else:
            v, pos = index(pos)
        pushed.append(v)
        return v

    for t in range(tris):
        code = data[codes + t]
        hi, lo = code >> 4, code & 15
        if hi < 15:
            a, b = edges[hi]
            if lo == 0:
                c = nxt
                nxt += 1
                verts.insert(0, c)
            elif lo < 13:
                c = verts[lo]
            elif lo < 15:
                c = last = (last - 1 if lo == 13 else last + 1) & 0xFFFFFFFF
                verts.insert(0, c)
            else:
                c, pos = index(pos)
                verts.insert(0, c)
            edges[:0] = [(a, c), (c, b)]          # (c, b) pushed, then (a, c): the latest first
        else:
            if lo < 14:
                zw = aux[lo]
                a = nxt
                nxt += 1
            else:
                zw = data[pos]
                pos += 1
                if zw == 0:
                    nxt = 0
                if lo == 14:
                    a = nxt
                    nxt += 1
                else:
                    a, pos = index(pos)
            pushed = [a]
            b, c = other(zw >> 4, lo >= 14, pushed), other(zw & 15, lo >= 14, pushed)
            edges[:0] = [(a, c), (c, b), (b, a)]
            verts[:0] = pushed[::-1]
        del edges[16:], verts[16:]
        out[3 * t:3 * t + 3] = (a, b, c)
    if pos != end:
        raise ValueError(f"{end - pos} bytes of triangle data left over")
    return out.astype(np.uint16 if stride == 2 else np.uint32)


def _indices(data: bytes, count: int, stride: int) -> np.ndarray:
    """Mode 2 (Appendix A): indices as zigzag deltas from one of two baselines."""
    if not data or data[0] != 0xD1:
        raise ValueError(f"index stream header {data[:1].hex() or 'missing'}, not d1")
    if stride not in (2, 4):
        raise ValueError(f"indices: byteStride {stride}")
    last = [0, 0]
    out = np.zeros(count, np.int64)
    pos, end = 1, len(data) - 4
    for i in range(count):
        v, pos = _varint(data, pos)
        base = v & 1
        delta = (~(v >> 2)) if v & 2 else (v >> 2)
        last[base] = (last[base] + delta) & 0xFFFFFFFF
        out[i] = last[base]
    if pos != end:
        raise ValueError(f"{end - pos} bytes of index data left over")
    return out.astype(np.uint16 if stride == 2 else np.uint32)
