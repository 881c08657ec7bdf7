"""Add-on preferences: the compute device, the field cache's memory limit and the engine's start-up warm-up.

``ADDON_ID`` is the add-on's package name: ``bl_ext.<repo>.aasdf`` when installed as an extension, ``aasdf`` when the
repository is loaded as a plain package (tests). Warp is not imported here: the device list is filled the first time
Blender asks for it (drawing the preferences), from the CUDA driver itself (``cuda_devices``: a few ``ctypes`` calls),
and ``aasdf_addon.runtime`` resolves the choice to a Warp device when the engine is first used.
"""

import ctypes
import sys

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty

ADDON_ID = __package__.rpartition(".")[0]

_CUDA_LIBRARIES = {"linux": ("libcuda.so.1", "libcuda.so"), "win32": ("nvcuda.dll",)}
_cuda_devices = None  # [(ordinal, name)], probed once
_device_items = None  # kept alive: Blender holds pointers into dynamic enum items


def _probe_cuda_devices() -> list[tuple[int, str]]:
    """(ordinal, name) of each CUDA device the NVIDIA driver reports; empty without a driver or a GPU."""
    for name in _CUDA_LIBRARIES.get(sys.platform, ()):
        try:
            cuda = ctypes.CDLL(name)
        except OSError:
            continue
        count = ctypes.c_int(0)
        if cuda.cuInit(0) != 0 or cuda.cuDeviceGetCount(ctypes.byref(count)) != 0:
            return []
        devices = []
        for ordinal in range(count.value):
            handle, label = ctypes.c_int(0), ctypes.create_string_buffer(256)
            if cuda.cuDeviceGet(ctypes.byref(handle), ordinal) == 0 and cuda.cuDeviceGetName(label, 256, handle) == 0:
                devices.append((ordinal, label.value.decode(errors="replace")))
        return devices
    return []


def cuda_devices() -> list[tuple[int, str]]:
    """The CUDA devices present, probed on first call only (registration does not probe)."""
    global _cuda_devices
    if _cuda_devices is None:
        _cuda_devices = _probe_cuda_devices()
    return _cuda_devices


def device_items(self, context):
    """Enum items of ``device``: ``CPU`` and one ``CUDA_<n>`` per CUDA device (value ``n + 1``)."""
    global _device_items
    if _device_items is None:
        _device_items = [("CPU", "CPU", "Run the engine's Warp kernels on the CPU", "NONE", 0)] + [
            (
                f"CUDA_{ordinal}",
                f"{name} (cuda:{ordinal})",
                f"Run the engine's Warp kernels on cuda:{ordinal}",
                "NONE",
                1 + ordinal,
            )
            for ordinal, name in cuda_devices()
        ]
    return _device_items


def reset_devices():
    """Probe the CUDA devices again the next time the list is needed."""
    global _cuda_devices, _device_items
    _cuda_devices = _device_items = None


class AASDF_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    device: EnumProperty(
        name="Device",
        description="Where the engine runs: the CPU, or a CUDA GPU when one is present",
        items=device_items,
        default=0,
    )
    cache_limit_mb: IntProperty(
        name="Cache Memory Limit",
        description="Memory the cache of input fields may use, in MB; 0 turns the cache off",
        default=1024,
        min=0,
        soft_max=16384,
    )
    warm_up: BoolProperty(
        name="Load Engine at Start-Up",
        description=(
            "Load the engine in the background a few seconds after Blender starts, so that the first boolean of a "
            "session does not wait for it (about a second; the engine takes about 170 MB of memory once loaded)"
        ),
        default=True,
    )

    def draw(self, context):
        draw_preferences(self.layout, self)


def draw_preferences(layout, prefs):
    """The preferences' settings (reads the cached device list only: nothing is probed or imported here)."""
    layout.use_property_split, layout.use_property_decorate = True, False
    layout.prop(prefs, "device")
    if _cuda_devices == []:
        layout.label(text="No CUDA device found: the engine runs on the CPU", icon="INFO")
    layout.prop(prefs, "cache_limit_mb")
    layout.prop(prefs, "warm_up")


def get(context=None):
    """The add-on's preferences, or ``None`` when the add-on has no entry in the preferences (a plain package)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None
