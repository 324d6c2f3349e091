"""mimica: anatomy-aware facial animation (retarget, simulate, wrinkle)."""

from ._memory import keep_memory
from .errors import MimicaError
from .mesh import Mesh, read_mesh, write_mesh

__version__ = "0.1.0"
__all__ = ["Mesh", "MimicaError", "keep_memory", "read_mesh", "write_mesh", "__version__"]
