"""How a process that imported the ``bpy`` module ends.

The ``bpy`` module of Blender 4.2 and 4.5 cannot end a Python process once an add-on with Python property callbacks
(``update=`` functions, ``items=`` functions of enums) has been registered: after Python has finalised, 4.2 crashes
(SIGSEGV, freeing Blender's space types) and 4.5 hangs (in a static destructor of its file-closing thread), whether
or not the add-on was unregistered first. Blender 5.0's module, and Blender's own executable, end normally. Where the
module cannot, the process ends here: Python's exit functions run (Blender's own among them), the output is flushed,
and the process leaves with its status without running the C++ destructors.
"""

import atexit
import os
import sys
import traceback

CLEAN_EXIT = (5, 0, 0)  # the first bpy module whose process ends normally with AASDF registered


def bpy_module():
    """The ``bpy`` this process imported when it is the Python module, not Blender's executable; else None.
    ``bpy.app.module`` says which where it exists (4.5 and later); 4.2's module leaves ``bpy.app.binary_path`` empty."""
    bpy = sys.modules.get("bpy")
    if bpy is None:
        return None
    module = getattr(bpy.app, "module", None)
    if module is None:  # Blender 4.2
        module = not bpy.app.binary_path
    return bpy if module else None


def needs_hard_exit() -> bool:
    """Whether this process imported a ``bpy`` module older than ``CLEAN_EXIT``."""
    bpy = bpy_module()
    return bpy is not None and tuple(bpy.app.version) < CLEAN_EXIT


def end_process(status: int) -> int:
    """Leave with ``status`` where the ``bpy`` module cannot end the process; elsewhere return ``status``."""
    if not needs_hard_exit():
        return status
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):  # closed or replaced
            pass
    os._exit(status)


def run_main(main) -> int:
    """``main()``'s exit status (an uncaught exception printed, as Python would, and counted as 1), after which a
    process whose ``bpy`` module cannot end it is ended here."""
    try:
        status = main()
    except SystemExit as done:
        status = done.code
    except BaseException:  # printed as the interpreter would, with the status it would give
        traceback.print_exc()
        status = 1
    if status is None:
        status = 0
    elif not isinstance(status, int):
        print(status, file=sys.stderr)
        status = 1
    return end_process(status)
