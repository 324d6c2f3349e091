"""`mimica view`: a live web viewer (three.js page, simulation streamed from Python)."""

from .server import ViewerServer
from .session import ViewerSession
from .vendor import ensure_three

__all__ = ["ViewerServer", "ViewerSession", "ensure_three"]
