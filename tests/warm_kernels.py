"""Compile the engine's kernels once, before a parallel test run starts its workers.

Each test worker would otherwise compile every Warp module it launches on its own, and the engine is loaded under two
names (``engine`` for the engine tests, ``aasdf.engine`` for the Blender tests, as Blender loads the extension), so a
fresh checkout would compile each module up to four times. Here every module is loaded once into the kernel cache
(``$WARP_CACHE_PATH``), one thread per core (Warp's compiler releases the GIL), and copied under the add-on's name
(``kernels.install_prebuilt``: a module's hash does not depend on its package). Modules already cached only load.

    python tests/warm_kernels.py
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDON_ENGINE = "aasdf.engine"


def main() -> None:
    sys.path.insert(0, str(ROOT))
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    import engine
    from engine.kernels import install_prebuilt, warp_modules

    wp.init()
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        list(pool.map(lambda module: wp.load_module(module, device="cpu"), warp_modules(engine.__name__)))
    cache = Path(wp.config.kernel_cache_dir)
    copied = sum(install_prebuilt(folder, cache, ADDON_ENGINE) for folder in sorted(cache.glob("wp_engine.*")))
    print(f"kernels ready in {time.perf_counter() - start:.1f} s ({copied} files copied for {ADDON_ENGINE})")


if __name__ == "__main__":
    main()
