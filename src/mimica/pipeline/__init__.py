"""The jobs a user runs, one function each, over the stages below: what the command line, the
viewer, the batch runner and the Blender add-on call.  Each job's options are a frozen
dataclass that holds its defaults once; progress is a callback; nothing here prints."""

from .addon import write_blender_addon
from .age import AgeOptions, age_sheet
from .animate import AnimateOptions, AnimateResult, animate
from .blendshapes import BlendshapesOptions, BlendshapesResult, make_blendshapes
from .fit_muscles import FitResult, fit_muscles
from .photos import PhotoOptions, transfer_photos
from .rig import RigOptions, make_rig
from .sequence import (ExportOptions, RenderOptions, export_sequence, read_mesh_sequence, read_values,
                       render_sequence)
from .simulate import SimulateOptions, SimulateResult, simulate
from .view import ViewedFace, ViewOptions, prepare_view
from .transfer import (TransferOptions, TransferResult, prepare_transfer, read_sequence, result_names,
                       transfer_sequence, write_results)

__all__ = [
    "write_blender_addon",
    "AgeOptions", "age_sheet",
    "AnimateOptions", "AnimateResult", "animate",
    "BlendshapesOptions", "BlendshapesResult", "make_blendshapes",
    "FitResult", "fit_muscles",
    "PhotoOptions", "transfer_photos",
    "RigOptions", "make_rig",
    "ExportOptions", "RenderOptions", "export_sequence", "read_mesh_sequence", "read_values", "render_sequence",
    "SimulateOptions", "SimulateResult", "simulate",
    "TransferOptions", "TransferResult", "prepare_transfer", "read_sequence", "result_names", "transfer_sequence",
    "write_results",
    "ViewedFace", "ViewOptions", "prepare_view",
]
