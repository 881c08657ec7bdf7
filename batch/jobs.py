"""Job files and the jobs in them: read (JSON lines or CSV, a job a line whose keys are the command line's long
options without the dashes), checked (a bad line becomes a failed job, the others go on), sliced (``--shard K/N``)
and sorted into those to run and those already done (their output newer than their inputs, made under the same
settings: a small record beside each output keeps the settings' hash). Imports neither ``bpy`` nor the engine."""

import csv
import hashlib
import json
import os
import shlex
from argparse import Namespace
from dataclasses import dataclass, field
from pathlib import Path

from .options import PATH_OPTIONS, RUN_OPTIONS, BatchError, check_args, job_parser

LIST_OPTIONS = ("inputs", "objects")
FLAG_OPTIONS = {
    "sharp_edges": ("--sharp-edges", "--no-sharp-edges"),
    "keep_faces": ("--keep-faces", "--no-keep-faces"),
    "remesh": ("--remesh", "--keep-faces"),  # (the command line's --remesh: keep_faces false)
}
TRUE, FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}
# Options that do not change what a job writes: left out of its settings' hash.
UNHASHED = ("output",)


@dataclass
class Job:
    """One job: ``number`` (1-based, in file order), ``where`` (``file:line``), ``options`` (the parsed options as
    a dict, paths absolute) or ``error`` (why the line cannot run)."""

    number: int
    where: str
    options: dict = field(default_factory=dict)
    error: str = ""

    @property
    def output(self) -> str:
        return self.options.get("output") or ""


def option_argv(key: str, value, folder: str, *, from_csv: bool) -> list:
    """The command-line words of one job key; relative paths made relative to ``folder``."""
    name = str(key).strip().replace("-", "_")
    if name in RUN_OPTIONS or (name not in JOB_KEYS and name not in FLAG_OPTIONS):
        raise BatchError(f"unknown key {str(key).strip()!r}")
    if value is None or (from_csv and str(value).strip() == ""):
        return []
    if name in FLAG_OPTIONS:
        text = str(value).strip().lower()
        if isinstance(value, bool) or text in TRUE | FALSE:
            return [FLAG_OPTIONS[name][0 if value is True or text in TRUE else 1]]
        raise BatchError(f"{name!r} must be true or false, not {value!r}")
    if name in LIST_OPTIONS:
        try:
            values = value if isinstance(value, list) else shlex.split(value) if from_csv else [value]
        except ValueError as err:  # (an unbalanced quote: this line fails, the others run)
            raise BatchError(f"{name!r}: {err}") from None
    elif isinstance(value, list | dict):
        raise BatchError(f"{name!r} takes one value, not {value!r}")
    else:
        values = [value]
    values = [str(item) for item in values]
    if name in PATH_OPTIONS:
        values = [os.path.normpath(os.path.join(folder, os.path.expanduser(item))) for item in values]
    return [f"--{name.replace('_', '-')}", *values] if values else []


JOB_KEYS = set(vars(job_parser({}).parse_args([])))


def parse_entry(entry: dict, folder: str, defaults: dict, *, from_csv: bool) -> dict:
    """One job's options (the command line's ``defaults`` overridden by ``entry``).

    Raises:
        BatchError: An unknown key or a bad value.
    """
    if not isinstance(entry, dict):
        raise BatchError(f"a job is an object of options, not {type(entry).__name__}")
    argv = [word for key, value in entry.items() for word in option_argv(key, value, folder, from_csv=from_csv)]
    return vars(job_parser(defaults).parse_args(argv))


def read_entries(path: Path):
    """``(line number, entry or an error message)`` for each job of a JSON-lines or CSV file."""
    text = path.read_text(encoding="utf-8-sig")
    if path.suffix.lower() == ".csv":
        rows = csv.DictReader(text.splitlines())
        for row in rows:
            if None in row:
                yield rows.line_num, f"more cells than the header has columns: {row[None]!r}"
            elif any(value and value.strip() for value in row.values()):
                yield rows.line_num, {key: value for key, value in row.items() if key is not None}
        return
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            yield number, json.loads(line)
        except json.JSONDecodeError as err:
            yield number, f"not a JSON object: {err.msg} (column {err.colno})"


def read_jobs(path, defaults: dict) -> list:
    """The jobs of the job file ``path``; those that cannot run carry their ``error``.

    Raises:
        BatchError: The file cannot be read at all.
    """
    path = Path(path)
    try:
        entries = list(read_entries(path))
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise BatchError(f"cannot read the job file {path}: {err}") from err
    folder, jobs, outputs = str(path.resolve().parent), [], {}
    for number, (line, entry) in enumerate(entries, start=1):
        job = Job(number, f"{path.name}:{line}")
        try:
            if isinstance(entry, str):
                raise BatchError(entry)
            job.options = parse_entry(entry, folder, defaults, from_csv=path.suffix.lower() == ".csv")
            check_args(Namespace(**job.options))
            first = outputs.setdefault(os.path.normcase(job.output), job.where)
            if first != job.where:
                raise BatchError(f"the same output as {first}: {job.output}")
        except BatchError as err:
            job.error = str(err)
        jobs.append(job)
    return _outputs_read_elsewhere(jobs)


def jobs_from_dicts(entries, defaults: dict, folder: str = ".") -> list:
    """Jobs from option dicts (``run_jobs``), relative paths relative to ``folder``."""
    jobs = []
    for number, entry in enumerate(entries, start=1):
        job = Job(number, f"job {number}")
        try:
            job.options = parse_entry(entry, os.path.abspath(folder), defaults, from_csv=False)
            check_args(Namespace(**job.options))
        except BatchError as err:
            job.error = str(err)
        jobs.append(job)
    return _outputs_read_elsewhere(jobs)


def _outputs_read_elsewhere(jobs: list) -> list:
    """``jobs`` with those whose output another job reads refused: it would overwrite that job's input, before or
    after it ran (jobs run in any order)."""
    read = {}
    for job in jobs:
        if not job.error:
            for path in [*job.options.get("inputs", []), *([job.options["blend"]] if job.options.get("blend") else [])]:
                read.setdefault(os.path.normcase(os.path.abspath(path)), job.where)
    for job in jobs:
        if not job.error and job.output:
            reader = read.get(os.path.normcase(os.path.abspath(job.output)))
            if reader is not None:
                job.error = f"{job.output} is an input of {reader}: write the result to another file"
    return jobs


def shard(jobs: list, spec: str | None) -> list:
    """The ``K``-th of ``N`` disjoint slices (``spec`` = ``"K/N"``, K from 1 to N): every N-th job from the K-th.

    Raises:
        BatchError: A malformed ``spec``.
    """
    if spec is None:
        return jobs
    try:
        k, n = (int(part) for part in spec.split("/"))
    except ValueError:
        raise BatchError(f"--shard takes K/N (for example 2/8), not {spec!r}") from None
    if not 1 <= k <= n:
        raise BatchError(f"--shard K/N needs 1 <= K <= N, not {spec!r}")
    return jobs[k - 1 :: n]


def settings_hash(options: dict) -> str:
    """A short hash of what decides a job's output (its inputs' paths and every option but the output's path)."""
    kept = {key: value for key, value in sorted(options.items()) if key not in UNHASHED}
    return hashlib.blake2b(json.dumps(kept, sort_keys=True, default=str).encode(), digest_size=8).hexdigest()


def record_path(output: str) -> str:
    """The small record kept beside an output: the settings it was made under and its numbers."""
    head, name = os.path.split(output)
    return os.path.join(head, f".{name}.aasdf.json")


def partial_dir(output: str) -> str:
    """The folder, beside the output, in which a job writes before moving its files into place."""
    head, name = os.path.split(output)
    return os.path.join(head, f".{name}.aasdf-partial")


def done_before(job: Job) -> dict | None:
    """The record of an up-to-date output (it exists, is newer than every input, and was made under the same
    settings), else None."""
    try:
        made = os.stat(job.output).st_mtime
        with open(record_path(job.output), encoding="utf-8") as handle:
            record = json.load(handle)
        sources = [*job.options["inputs"], *filter(None, [job.options.get("blend")])]
        newest = max((os.stat(path).st_mtime for path in sources), default=0.0)
    except (OSError, ValueError):
        return None
    if record.get("settings") != settings_hash(job.options) or made < newest:
        return None
    return record


def write_record(job: Job, numbers: dict) -> None:
    """Keep the settings' hash and the numbers of a job's output beside it (written atomically)."""
    path = record_path(job.output)
    temporary = f"{path}.{os.getpid()}.tmp"
    with open(temporary, "w", encoding="utf-8") as handle:
        json.dump({"settings": settings_hash(job.options), **numbers}, handle)
    os.replace(temporary, path)
