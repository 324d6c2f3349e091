"""What the glTF 2.0 specification fixes and every glTF module here reads: component types and
their numpy types, element widths, buffer-view targets, and the document's extension lists (the
reader and writer in gltf.py, the decoders of compressed geometry in draco.py and meshopt.py)."""

from __future__ import annotations

import numpy as np

FLOAT, SHORT, BYTE, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5122, 5120, 5121, 5123, 5125
COMPONENT = {BYTE: np.int8, UNSIGNED_BYTE: np.uint8, SHORT: np.int16, UNSIGNED_SHORT: np.uint16,
             UNSIGNED_INT: np.uint32, FLOAT: np.float32}
NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def drop_extension(doc: dict, name: str) -> None:
    """A glTF document's extension `name` taken out of its extensionsUsed and extensionsRequired
    (a list left empty goes too): once no part of the file uses it."""
    for k in ("extensionsUsed", "extensionsRequired"):
        if name in (doc.get(k) or []):
            doc[k] = [e for e in doc[k] if e != name]
            if not doc[k]:
                del doc[k]
