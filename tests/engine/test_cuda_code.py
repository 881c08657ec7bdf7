"""Every engine kernel translates to CUDA, without a GPU.

This machine has no NVIDIA GPU, so no test launches a kernel on CUDA. What can break the CUDA path in the engine's own
code is what Warp refuses when it generates CUDA C++ from a kernel (a CPU-only construct, a type that does not
resolve for the device): Warp's code generator is run here for every module with the options a CUDA load uses. The
generated code's compilation by NVRTC (about a minute a module and architecture on this CPU) runs when the extension
zips are built (``make extension``: PTX for ``engine.kernels.CUDA_ARCHS``), not in the tests.
"""

import re

import pytest
import warp as wp
from warp._src.context import ModuleBuilder  # Warp's code generator; its public entry points also compile

import engine
from engine.kernels import ENGINE_MODULES, warp_modules


@pytest.mark.parametrize("module", warp_modules(engine.__name__), ids=list(ENGINE_MODULES))
def test_every_kernel_of_the_module_generates_cuda_code(module):
    wp.init()
    built = wp.get_module(module.__name__)
    options = {**built.options, "block_dim": 256, "output_arch": 86}
    source = ModuleBuilder(built, options, target="cuda").codegen("cuda")
    entries = set(re.findall(r"__global__ void ([A-Za-z0-9_]+?)_[0-9a-f]{8}_cuda_kernel_forward\(", source))
    assert entries == {kernel.key for kernel in built.kernels.values()}
