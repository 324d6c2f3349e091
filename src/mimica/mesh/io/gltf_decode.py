"""A glTF's JSON made into pygltflib's objects, as pygltflib makes them, 20-30x sooner.

pygltflib decodes through dataclasses_json, which looks up every object's type hints again: a
Blender export of a head with 52 shape keys (1,300 accessors) took 0.9 s of its 1.4 s read there.
Here each pygltflib class's fields are looked up once and the objects built by their own
constructors -- the same objects (dataclass equality, checked on every glTF the tests and the
benches write and read, Blender's exports and the Khronos samples included; tests/mesh): floats
where pygltflib declares floats, a primitive's `attributes` an `Attributes`, its morph targets
left as dicts, a missing field its default.  A field of the wrong JSON kind is refused
(TypeError), as pygltflib refuses it.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import typing

_PLANS: dict = {}


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _kind(v, want, what):
    if v is not None and not isinstance(v, want):
        raise TypeError(f"glTF {what}: {type(v).__name__} where {want.__name__} is expected")
    return v


def _converter(tp, gl):
    """How a JSON value of field type `tp` becomes what pygltflib makes of it (None: as it is)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Union:
        rest = [a for a in args if a is not type(None)]
        return _converter(rest[0], gl) if len(rest) == 1 else None
    if origin is list:
        if not args or args[0] is gl.Attributes:      # morph targets: pygltflib leaves them dicts
            return lambda v: _kind(v, list, "list")
        inner = _converter(args[0], gl)
        if inner is None:
            return lambda v: _kind(v, list, "list")
        return lambda v: v if v is None else [inner(x) for x in _kind(v, list, "list")]
    if tp is float:
        return lambda v: float(v) if _is_int(v) else v
    if tp is gl.Attributes:
        return lambda v: v if v is None else gl.Attributes(**_kind(v, dict, "attributes"))
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return lambda v: v if v is None else _decode(tp, _kind(v, dict, tp.__name__), gl)
    return None


def _decode(cls, d: dict, gl):
    plan = _PLANS.get(cls)
    if plan is None:
        hints = typing.get_type_hints(cls)
        plan = _PLANS[cls] = {f.name: _converter(hints[f.name], gl) for f in dataclasses.fields(cls) if f.init}
    return cls(**{k: (plan[k](v) if plan[k] else v) for k, v in d.items() if k in plan})


@functools.lru_cache(maxsize=None)
def fast_gltf_class():
    """pygltflib.GLTF2 with its JSON decoded here (load, load_binary as pygltflib's)."""
    import pygltflib as gl

    class FastGLTF2(gl.GLTF2):
        @classmethod
        def from_json(cls, s, *, infer_missing=False, **kw):
            return _decode(cls, _kind(json.loads(s), dict, "document"), gl)

    return FastGLTF2
