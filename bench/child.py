"""Run a benchmark measurement in a fresh Python process (its own peak memory, its own kernel cache state)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_child(script: str, *args, cache: str | None = None) -> dict:
    """Run ``script`` with ``python -c`` and arguments ``ROOT, *args``; return the JSON it prints after ``RESULT ``.

    ``cache``: the Warp kernel cache to use (default: ``WARP_CACHE_PATH`` or the checkout's ``.warp-cache``).
    """
    default = os.environ.get("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))
    env = {**os.environ, "WARP_CACHE_PATH": cache or default}
    out = subprocess.run(
        [sys.executable, "-c", script, str(ROOT), *(str(a) for a in args)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    line = next(line for line in out.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])
