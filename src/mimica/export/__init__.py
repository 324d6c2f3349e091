"""Take it home: ARKit blendshapes for any head, glTF sequences."""

from .blendshapes import ARKIT_52, arkit_blendshapes, ict_sources
from ..store import TemplateStore

__all__ = ["ARKIT_52", "arkit_blendshapes", "ict_sources", "TemplateStore"]
