"""Run every benchmark of ``make bench`` in turn and write their tables into ``bench/RESULTS.md``.

Each script prints markdown (a ``#`` title line, prose and tables); this collects their output under one header
naming the date, the commit and the machine, dropping the lines Warp prints as it loads its modules. A script that
fails leaves its error in the file and the run goes on.

    .venv/bin/python bench/run_all.py [--scripts construction pipeline ...] [--output bench/RESULTS.md]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = (
    "construction",
    "pipeline",
    "addon",
    "cold_start",
    "scaling",
    "breakdown",
    "sharp",
    "adaptivity",
    "signs",
    "offset",
    "batch",
)
# Lines Warp prints at start-up and per module it loads: not results.
NOISE = ("Warp ", "Module ", "   CUDA", "   Devices", '     "cpu"', "   Kernel cache", "     /")


def commit() -> str:
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True)
    return done.stdout.strip() + ("+changes" if dirty.stdout.strip() else "")


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()} (Warp on its CPU device)"


def run_script(name: str) -> str:
    done = subprocess.run(
        [sys.executable, str(ROOT / "bench" / f"{name}.py")], cwd=ROOT, capture_output=True, text=True, check=False
    )
    lines = [line for line in done.stdout.splitlines() if not line.startswith(NOISE)]
    text = "\n".join(lines).strip()
    if done.returncode != 0:
        text += f"\n\n`bench/{name}.py` failed (exit {done.returncode}):\n\n```\n{done.stderr[-3000:]}\n```"
    return text


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scripts", nargs="+", default=list(SCRIPTS), choices=SCRIPTS)
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "RESULTS.md")
    args = parser.parse_args(argv)
    header = (
        "# Benchmark results\n\n"
        f"Written by `make bench` (`bench/run_all.py`) on {datetime.date.today().isoformat()} at commit {commit()}, "
        f"on {machine()}. Each section is one script's output; `bench/README.md` says what each compares. Times drift "
        "10-20 % within minutes on this machine: AASDF and what it is compared with run in alternating rounds, and "
        "a ratio is the median of the per-round ratios with the smallest and largest beside it.\n"
    )
    sections = []
    for name in args.scripts:
        print(f"run_all: bench/{name}.py", flush=True)
        text = run_script(name)
        # each script's own title becomes a section
        text = "\n".join(("#" + line if line.startswith("# ") else line) for line in text.splitlines())
        sections.append(text)
        args.output.write_text(header + "\n" + "\n\n".join(sections) + "\n", encoding="utf-8")
    print(f"run_all: wrote {args.output}")


if __name__ == "__main__":
    main()
