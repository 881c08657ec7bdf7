"""AASDF engine: algebraic adaptive signed distance fields of triangle meshes, their booleans, field operations
(re-distancing, offset, shell, thickness) and surfaces.

Pure numpy + NVIDIA Warp (never Blender): arrays in, arrays out. Kernels run on Warp's default device, or the one
passed as ``device`` (CPU here, CUDA wherever an NVIDIA GPU is present). Negative inside, positive outside.
"""

from . import kernels
from .boolean import difference, intersection, union
from .build import build_field, build_fields
from .components import connected_components
from .edges import fold_edges, surface_edges
from .errors import AasdfError
from .field import AdaptiveField
from .fieldops import offset, shell
from .hostpool import pooled_bytes, release_memory
from .plan import check_meshes, check_resolvable, plan_field, tune_allocator
from .redistancing import redistance
from .sources import interpolate_corners

kernels.configure_modules(__name__)
tune_allocator()  # large arrays back to the system when freed (see plan.MMAP_THRESHOLD)

__all__ = [
    "AasdfError",
    "AdaptiveField",
    "build_field",
    "build_fields",
    "check_meshes",
    "check_resolvable",
    "connected_components",
    "fold_edges",
    "difference",
    "interpolate_corners",
    "intersection",
    "offset",
    "plan_field",
    "pooled_bytes",
    "redistance",
    "release_memory",
    "shell",
    "surface_edges",
    "union",
]
