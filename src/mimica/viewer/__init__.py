"""`mimica view`: a live web viewer (three.js page, simulation streamed from Python)."""

from .server import ViewerServer, port_in_use
from .session import ViewerSession
from .vendor import ensure_three

__all__ = ["ViewerServer", "ViewerSession", "ensure_three", "port_in_use"]
