"""Run stages with content-hash caching.

A stage's key is the SHA-256 of (stage name, its parameters, the robocal version, a
fingerprint of robocal's own source and schemas, and the keys of the stages it requires —
for ingest, the SHA-256 of the recording).  A stage whose
``stage.json`` has the same key and whose recorded outputs are all present and unchanged is
*cached*: nothing is run.  Changing a parameter changes that stage's key and, through the
chain, the keys of every stage after it.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import inspect
import json
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

from pipeline import __version__
from pipeline.errors import RobocalError
from pipeline.stages.artefacts import STAGE_FILE, dumps, read_stage, sha256_file, write_json
from pipeline.stages.registry import BY_NAME, STAGES, Stage
from pipeline.stages.results import gather
from pipeline.stages.runfolder import STAGE_MARKER, claim, fresh_stage_dir, locked, record_manifest

class StageFailed(RobocalError):
    """A stage reported `status: fail` (e.g. a validation check); the run stops."""


@dataclass
class Outcome:
    stage: str
    cached: bool
    elapsed_s: float
    key: str
    summary: dict
    cpu_s: float = 0.0  # CPU time of this process (user + system) while the stage ran


@functools.cache
def code_fingerprint() -> str:
    """SHA-256 over robocal's Python sources and JSON Schemas (path and bytes), so that a
    change of code re-runs the stages even without a version bump (~100 small files, ms)."""
    from pipeline.recording.schemas import schema_dir

    pkg = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for root, pattern in ((pkg, "*.py"), (schema_dir(), "*.json")):
        for f in sorted(root.rglob(pattern)):
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def stage_key(name: str, params: dict, inputs: dict[str, str], version: str = __version__) -> str:
    """SHA-256 over the canonical JSON of what determines a stage's output."""
    doc = {"stage": name, "params": params, "inputs": inputs, "robocal_version": version,
           "code": code_fingerprint()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def is_available(stage: Stage) -> bool:
    """The stage's module exists (found without importing it: a cached run imports nothing heavy)."""
    try:
        return importlib.util.find_spec(stage.module) is not None
    except ModuleNotFoundError:
        return False


def load_module(stage: Stage) -> ModuleType | None:
    """The stage's module, or None for an optional stage whose module does not exist (yet)."""
    if stage.optional and not is_available(stage):
        return None
    return importlib.import_module(stage.module)


def available_stages() -> list[Stage]:
    return [s for s in STAGES if not s.optional or is_available(s)]


def _outputs(run_dir: Path, name: str, summary: dict) -> dict[str, str]:
    """Every file the stage wrote (its folder and any extra `outputs`), path → SHA-256."""
    run_dir = Path(run_dir)
    files = [p for p in sorted((run_dir / name).rglob("*")) if p.is_file() and p.name not in (STAGE_FILE, STAGE_MARKER)]
    files += [run_dir / o for o in summary.get("outputs", []) if (run_dir / o).is_file()]
    return {p.relative_to(run_dir).as_posix(): sha256_file(p) for p in files}


def is_fresh(run_dir: Path, doc: dict | None, key: str) -> bool:
    """The stage.json matches `key` and its outputs are present and unchanged."""
    if not doc or doc.get("key") != key:
        return False
    for rel, digest in doc.get("outputs", {}).items():
        p = Path(run_dir) / rel
        if not p.is_file() or sha256_file(p) != digest:
            return False
    return True


def _call(fn: Callable, run_dir: Path, params: dict) -> Any:
    """`run(run_dir, params)`; a stage whose `run` takes keyword parameters gets them as such."""
    sig = inspect.signature(fn)
    if "params" in sig.parameters or len(sig.parameters) == 2 and not any(
            p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return fn(run_dir, params)
    accepts_all = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
    kwargs = {k: v for k, v in params.items() if accepts_all or k in sig.parameters}
    return fn(run_dir, **kwargs)


def input_keys(run_dir: Path, stage: Stage, recording: Path | None = None) -> dict[str, str]:
    """Keys of the stages `stage` requires (or the recording's hash for ingest)."""
    if not stage.requires:
        if recording is None:
            raise RobocalError(f"stage {stage.name} needs a recording")
        return {"recording_sha256": sha256_file(recording)}
    keys = {}
    for dep in stage.requires:
        spec = BY_NAME[dep]
        doc = read_stage(run_dir, dep)
        if doc is None:
            if spec.optional and not is_available(spec):
                continue
            raise RobocalError(f"{run_dir}: stage {dep!r} has not been run (run `robocal {dep}` or `robocal run` first)")
        if doc.get("summary", {}).get("status") == "fail":
            raise StageFailed(f"{run_dir}: stage {dep!r} failed: {doc['summary'].get('reason', '')}")
        keys[dep] = doc["key"]
    return keys


def run_stage(run_dir: Path, name: str, params: dict | None = None, recording: Path | None = None,
              force: bool = False, log: Callable[[str], None] | None = None) -> Outcome:
    """Run one stage unless it is cached.  Raises StageFailed when its summary says fail.
    Holds the run folder's lock; writes only into a folder robocal created (`runfolder`)."""
    if name not in BY_NAME:
        raise RobocalError(f"unknown stage {name!r} (stages: {', '.join(BY_NAME)})")
    with locked(run_dir, log=log):
        claim(run_dir)
        return _run_stage(Path(run_dir), name, params, recording, force, log)


def _run_stage(run_dir: Path, name: str, params: dict | None, recording: Path | None,
               force: bool, log: Callable[[str], None] | None) -> Outcome:
    stage = BY_NAME[name]
    if not is_available(stage):
        raise RobocalError(f"stage {name!r} is not available (module {stage.module} missing)")
    p = {**stage.defaults, **(params or {})}
    if recording is None and not stage.requires:
        prev = read_stage(run_dir, name)
        if prev is None:
            raise RobocalError(f"{run_dir}: stage {name} needs a recording")
        recording = Path(prev["params"]["recording"])
    inputs = input_keys(run_dir, stage, recording)
    key = stage_key(name, p, inputs)
    prev = read_stage(run_dir, name)
    if not force and is_fresh(run_dir, prev, key):
        out = Outcome(name, True, 0.0, key, prev.get("summary", {}))
    else:
        mod = load_module(stage)
        t0, c0 = time.perf_counter(), time.process_time()
        fresh_stage_dir(run_dir, name)
        call_params = dict(p)
        if recording is not None:
            call_params["recording"] = str(Path(recording).resolve())
        try:
            summary = _call(mod.run, run_dir, call_params) or {}
        except BaseException as e:  # the run's results must not look like a pass after a crash
            why = str(e) if isinstance(e, RobocalError) else f"{type(e).__name__}: {e}"
            try:
                record_manifest(run_dir / name)
                write_results(run_dir, error=f"stage {name} stopped: {why}")
            except OSError:
                pass
            raise
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        doc = {"stage": name, "key": key, "params": {**p, **({"recording": call_params["recording"]}
                                                              if "recording" in call_params else {})},
               "inputs": inputs, "elapsed_s": elapsed, "cpu_s": cpu, "robocal_version": __version__,
               "summary": summary, "outputs": _outputs(run_dir, name, summary)}
        (run_dir / name / STAGE_FILE).write_text(dumps(doc))
        record_manifest(run_dir / name)
        out = Outcome(name, False, elapsed, key, summary, cpu)
    if log:
        log(f"{name}: " + ("cached" if out.cached else f"ran in {out.elapsed_s:.2f} s, CPU {out.cpu_s:.2f} s") + f" (key {key[:12]})")
    write_results(run_dir)
    if out.summary.get("status") == "fail":
        raise StageFailed(f"{name} failed: {out.summary.get('reason', 'see ' + str(run_dir / name))}")
    return out


def run_pipeline(recording: Path, run_dir: Path, params: dict[str, dict] | None = None,
                 stages: list[str] | None = None, force: bool = False,
                 log: Callable[[str], None] | None = None) -> list[Outcome]:
    """Every available stage in order (or `stages`), each cached when nothing changed.  The
    recording is read (and decompressed) once for the whole run."""
    from pipeline.recording.reader import cached_reads

    recording, run_dir = Path(recording), Path(run_dir)
    if not recording.is_file():
        raise RobocalError(f"{recording}: no such file")
    params = params or {}
    names = stages or [s.name for s in available_stages()]
    outcomes = []
    with locked(run_dir, log=log), cached_reads():
        claim(run_dir)
        for name in names:
            outcomes.append(run_stage(run_dir, name, params.get(name), recording if name == "ingest" else None,
                                      force=force, log=log))
    return outcomes


def write_results(run_dir: Path, error: str | None = None) -> dict:
    """DIR/results.json: the summaries of every stage run so far, plus the headline figures;
    `error` (a stage that stopped) makes the status `fail` with that reason."""

    doc = gather(run_dir)
    if error is not None:
        doc["summary"]["status"] = "fail"
        doc["summary"]["error"] = error
    write_json(Path(run_dir) / "results.json", doc)
    return doc
