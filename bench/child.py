"""Run benchmark measurements in fresh Python processes (their own peak memory, kernel cache state and engine)."""

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


class Worker:
    """A worker process running ``script`` (a benchmark file) as ``script --worker root cache``: it reads one request a
    line on stdin and answers each with one JSON line prefixed ``@@`` (other output is ignored), so two checkouts'
    engines can be timed in turns, each imported in a process of its own."""

    def __init__(self, script: str, root: Path, cache: Path):
        self.process = subprocess.Popen(
            [sys.executable, script, "--worker", str(root), str(cache)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    def ask(self, request: str) -> dict:
        """Send one request line; return the worker's answer."""
        self.process.stdin.write(request + "\n")
        self.process.stdin.flush()
        for line in self.process.stdout:
            if line.startswith("@@"):
                return json.loads(line[2:])
        raise SystemExit(f"a worker stopped on {request!r}")

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


# Where a checkout other than this one compiles its kernels: nothing is written into it.
AGAINST_CACHE = Path("/tmp/aasdf-against-cache")


def against_workers(script: str, before: Path, after: Path = ROOT) -> tuple[Worker, Worker]:
    """Workers running ``script`` on checkout ``after`` (default: this one) and on ``before``: (ours, theirs)."""
    after, before = Path(after).resolve(), Path(before).resolve()
    ours = Worker(script, after, after / ".warp-cache" if after == ROOT else AGAINST_CACHE)
    return ours, Worker(script, before, AGAINST_CACHE)


def alternate(ours: Worker, theirs: Worker, request: str, rounds: int) -> tuple[list, list]:
    """One warm-up ``request`` to each (kernels compiled or loaded), then ``rounds`` rounds, ours first in even rounds
    and theirs first in odd ones (see ``bench/paired.py``): (our answers, theirs)."""
    ours.ask(request)
    theirs.ask(request)
    answers = {id(ours): [], id(theirs): []}
    for k in range(rounds):
        for side in (ours, theirs) if k % 2 == 0 else (theirs, ours):
            answers[id(side)].append(side.ask(request))
    return answers[id(ours)], answers[id(theirs)]
