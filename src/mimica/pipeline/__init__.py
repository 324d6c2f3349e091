"""The jobs a user runs, one function each, over the stages below: what the command line, the
viewer, the batch runner and the Blender add-on call.  Each job's options are a dataclass that
holds its defaults once; progress is a callback given one line of text; nothing here prints."""

from .blendshapes import BlendshapesOptions, BlendshapesResult, make_blendshapes
from .age import AgeOptions, age_sheet
from .animate import AnimateOptions, AnimateResult, animate
from .rig import RigOptions, make_rig
from .sequence import (ExportOptions, RenderOptions, export_sequence, read_mesh_sequence, read_values,
                       render_sequence)
from .simulate import SimulateOptions, SimulateResult, simulate
from .transfer import (TransferOptions, TransferResult, prepare_transfer, read_sequence, result_names,
                       transfer_sequence, write_results)

__all__ = ["BlendshapesOptions", "BlendshapesResult", "make_blendshapes", "TransferOptions", "TransferResult",
           "AgeOptions", "age_sheet", "AnimateOptions", "AnimateResult", "animate", "ExportOptions", "RenderOptions", "export_sequence", "read_mesh_sequence",
           "read_values", "render_sequence", "RigOptions", "make_rig", "SimulateOptions", "SimulateResult", "simulate", "prepare_transfer", "read_sequence", "result_names", "transfer_sequence", "write_results"]
