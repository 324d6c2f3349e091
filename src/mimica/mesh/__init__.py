"""Mesh data type and file IO."""

from .core import Mesh, plane_grid, vertex_normals
from .io import MESH_SUFFIXES, atomic_path, read_json, read_mesh, read_vertices, validate, write_glb, write_mesh

__all__ = ["Mesh", "plane_grid", "vertex_normals", "read_mesh", "write_mesh", "write_glb", "validate",
           "atomic_path", "read_json", "read_vertices", "MESH_SUFFIXES"]
