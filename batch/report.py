"""What a batch run shows and keeps: this script's own lines while Blender's output is silenced, a progress bar with
rate, ETA and failures on a terminal (tqdm, when it can be imported: Blender's own Python lacks it) or a plain line
per job otherwise, and the JSON report (``--report``: per job status, seconds, triangles, volume, message; rewritten
every few seconds as jobs end, so a killed run leaves what it did)."""

import json
import os
import sys
import time
from contextlib import contextmanager

STATUSES = ("done", "skipped", "failed")
REPORT_EVERY = 5.0  # seconds between rewrites of the report while jobs run (a killed run keeps what it did)


@contextmanager
def blender_output_silenced(active: bool):
    """Send what Blender prints to stdout (importers' timings, operator reports) to the null device; yields the
    stream on which this script's own lines still reach the terminal."""
    if not active:
        yield sys.stdout
        return
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.close(null)
    stdout = sys.stdout
    out = os.fdopen(saved, "w", buffering=1)
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (closed below)
    try:
        yield out
    finally:
        sys.stdout.close()
        sys.stdout = stdout
        out.flush()
        os.dup2(saved, 1)
        out.close()


def silence_stdout():
    """For a worker process: everything written to stdout (Blender's and Warp's lines) goes to the null device."""
    sys.stdout.flush()
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.close(null)


def entry(job, outcome: dict) -> dict:
    """A job's line of the report."""
    return {
        "job": job.number,
        "where": job.where,
        "output": job.output,
        "status": outcome["status"],
        "seconds": outcome.get("seconds", 0.0),
        "triangles": outcome.get("triangles"),
        "volume": outcome.get("volume"),
        "fields_built": outcome.get("fields_built", 0),
        "message": outcome.get("message", ""),
    }


class Progress:
    """Counts the jobs as they end and shows them: a tqdm bar on a terminal, else a line per job on ``out``.
    Failures are always printed, with their reason, on ``err``."""

    def __init__(self, total: int, out, err, *, quiet: bool = False, report=None, every: float = REPORT_EVERY):
        self.total, self.out, self.err, self.quiet = total, out, err, quiet
        self.entries, self.start = [], time.perf_counter()
        self.report, self.every, self.written = report, every, self.start  # the report, rewritten as jobs end
        self.counts = dict.fromkeys(STATUSES, 0)
        self.bar = None
        if not quiet and total and getattr(err, "isatty", lambda: False)():
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=total, unit="job", file=err, dynamic_ncols=True, desc="aasdf_batch")

    def add(self, job, outcome: dict):
        line = entry(job, outcome)
        self.entries.append(line)
        self.counts[line["status"]] += 1
        if self.report is not None and time.perf_counter() - self.written >= self.every:
            write_report(self.report, self.summary(), self.entries)
            self.written = time.perf_counter()
        if line["status"] == "failed":
            self.say(f"aasdf_batch: failed: {job.where}: {line['message']}", self.err)
        if self.bar is not None:
            self.bar.set_postfix(failed=self.counts["failed"], refresh=False)
            self.bar.update(1)
        elif not self.quiet and line["status"] != "failed":
            numbers = f"{line['triangles']:,} triangles, {line['seconds']:.2f} s" if line["triangles"] else ""
            self.say(f"aasdf_batch: [{len(self.entries)}/{self.total}] {line['status']} {line['output']} {numbers}")

    def say(self, text: str, stream=None):
        if self.bar is not None:
            self.bar.write(text, file=stream or self.out)
        else:
            print(text, file=stream or self.out, flush=True)

    def summary(self) -> dict:
        """The counts so far (``jobs`` ended out of ``total``)."""
        seconds = time.perf_counter() - self.start
        return {"jobs": len(self.entries), "total": self.total, **self.counts, "seconds": round(seconds, 3)}

    def close(self) -> dict:
        """End the bar, print the summary line, write the report (when asked); returns the summary."""
        if self.bar is not None:
            self.bar.close()
        summary = self.summary()
        seconds = summary["seconds"]
        if self.report is not None:
            write_report(self.report, summary, self.entries)
        self.say(
            f"aasdf_batch: {summary['jobs']} jobs: {self.counts['done']} done, {self.counts['skipped']} up to date, "
            f"{self.counts['failed']} failed, {seconds:.1f} s"
        )
        return summary


def write_report(path, summary: dict, entries: list) -> None:
    """The JSON report, jobs in file order, written atomically."""
    path = os.path.abspath(path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    temporary = f"{path}.{os.getpid()}.tmp"
    with open(temporary, "w", encoding="utf-8") as handle:
        json.dump({"summary": summary, "jobs": sorted(entries, key=lambda e: e["job"])}, handle, indent=1)
    os.replace(temporary, path)
