"""Hostile and damaged input — one test per kind of damage (a dead or frozen device is in
test_acquire_dead_device.py).  Each failed on the code before the fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import ROBOCAL, run_cli
from hostile_support import BUNDLED, bomb, chunk_offsets, edit_json, rebuild, replace_chunk
from pipeline.errors import RobocalError
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT

DELTA, SCANNER, ARC = BUNDLED["delta-tracker"], BUNDLED["scorbot-scanner"], BUNDLED["arc-welder-touch"]


def one_line_error(proc, *needles: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = [ln for ln in proc.stderr.strip().splitlines() if "robocal: error:" in ln]
    assert len(line) == 1, proc.stderr[-3000:]
    for n in needles:
        assert n in line[0], (n, line[0])
    return line[0]


def ingest_validate(rec, out):
    return run_cli("run", rec, "--out", out, "--stages", "ingest,validate")


def error_in_process(rec, out, *needles: str, calibrate: bool = False) -> str:
    """The one-line `RobocalError` that `robocal run --stages ingest,validate` (or `robocal
    calibrate`) stops with, found in this process (what the CLI prints, without its start-up)."""
    from pipeline.stages.runner import run_pipeline

    with pytest.raises(RobocalError) as e:
        if calibrate:
            from pipeline.calibrate import calibrate as cal
            cal(rec, out, k_folds=2)
        else:
            run_pipeline(rec, out, stages=["ingest", "validate"])
    msg = str(e.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, (n, msg)
    return msg


# ----- 1. decompression bombs: limits before decompressing, one read per run ----------------------
@pytest.mark.parametrize("kind,size,limit", [("zstd", 1 << 30, "ROBOCAL_MAX_CHUNK_MB"), ("lz4", 1 << 30, "ROBOCAL_MAX_CHUNK_MB"),
                                             ("zstd", 1 << 27, "ROBOCAL_MAX_RATIO")])
def test_1_decompression_bomb_is_refused_before_decompressing(tmp_path, kind, size, limit):
    bad = tmp_path / f"bomb-{kind}.mcap"
    bad.write_bytes(replace_chunk(DELTA.read_bytes(), 0, bomb(kind, size)))
    assert bad.stat().st_size < 10 << 20
    code = ("import resource,time,sys; from pipeline.recording.reader import read_recording; t=time.process_time();"
            f"r=read_recording({str(bad)!r}); print(time.process_time()-t, "  # VmHWM: this exec's peak, not the parent's
            "[ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')][0], "
            "sum(map(len, r.messages.raw.values()))); "
            "print(*r.warnings, sep='\\n')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    cpu, rss_kb, kept = p.stdout.split("\n")[0].split()
    assert float(cpu) < 2.0 and int(rss_kb) < 400_000  # was 3 min 34 s, 1.18 GB
    assert limit in p.stdout and "not decompressed" in p.stdout and "messages are lost" in p.stdout


def test_1_a_frame_that_lies_about_its_size_cannot_expand(tmp_path):
    from pipeline.recording import framing

    size = framing.ReadLimits().ratio_floor_bytes  # below the ratio test: only the output cap stops it

    def liar(c):
        out = bomb("zstd", 1 << 28)(c)
        out.uncompressed_size = size
        return out

    bad = tmp_path / "liar.mcap"
    bad.write_bytes(replace_chunk(DELTA.read_bytes(), 0, liar))
    t = time.process_time()
    rec = read_recording(bad)
    assert time.process_time() - t < 1.0
    assert any("expands to more than" in w for w in rec.warnings), rec.warnings


def test_1_limits_are_configurable(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOCAL_MAX_CHUNK_MB", "0.1")
    rec = read_recording(DELTA)  # its one chunk is 0.4 MB uncompressed
    assert not rec.messages.raw.get("/tracker/point")
    assert any("ROBOCAL_MAX_CHUNK_MB" in w for w in rec.warnings)


def test_1_a_run_decompresses_the_recording_once(tmp_path, monkeypatch):
    from pipeline.recording import framing
    from pipeline.stages.runner import run_pipeline

    calls = []
    real = framing.decompress_chunk
    monkeypatch.setattr(framing, "decompress_chunk", lambda *a: calls.append(1) or real(*a))
    run_pipeline(DELTA, tmp_path / "run", stages=["ingest", "validate"])
    assert len(calls) == len(chunk_offsets(DELTA.read_bytes())) == 1


# ----- 2. tracebacks become one line ------------------------------------------------------------
@pytest.mark.parametrize("case,fn,needles", [
    ("deep-json", lambda m: b'{"a":' * 5000 + b"1" + b"}" * 5000, ["record 3", "not valid JSON"]),
    ("timestamp-string", lambda m: {**m, "timestamp_ns": "soon"}, ["record 3", "timestamp_ns"]),
    ("timestamp-2^70", lambda m: {**m, "timestamp_ns": 2 ** 70}, ["record 3", "out of range"]),
    ("timestamp-1e300", lambda m: {**m, "timestamp_ns": 1e300}, ["record 3", "out of range"]),
    ("joints-overflow", lambda m: json.dumps({**m, "joint_positions": ["X", 0, 0]}).replace('"X"', "1e400").encode(),
     ["(3)", "NaN or infinite"]),
    ("joints-wrong-type", lambda m: {**m, "joint_positions": {"a": 1}}, ["record 3", "joint_positions"]),
])
def test_2_wrong_json_is_one_line_naming_the_record(tmp_path, case, fn, needles):
    bad = rebuild(DELTA, tmp_path / f"{case}.mcap", msg=edit_json("/tracker/point", 3, fn))
    if case == "deep-json":  # the whole command line once; the rest in process
        one_line_error(ingest_validate(bad, tmp_path / "o"), str(bad), "/tracker/point", *needles)
    else:
        error_in_process(bad, tmp_path / "o", str(bad), "/tracker/point", *needles)


@pytest.mark.parametrize("case,edit,needles", [
    ("system-not-string", lambda md: {**md, META_CAMPAIGN: {**md[META_CAMPAIGN], "system": ["delta-tracker"]}},
     [META_CAMPAIGN, "system"]),
    ("model-nan", lambda md: {**md, META_ROBOT: {**md[META_ROBOT], "l1": float("nan")}}, [META_ROBOT, "l1"]),
    ("model-inf", lambda md: {**md, META_ROBOT: {**md[META_ROBOT], "a": float("inf")}}, [META_ROBOT, "a"]),
    ("model-1e308", lambda md: {**md, META_ROBOT: {**md[META_ROBOT], "l2": 1e308}}, [META_ROBOT, "l2"]),
    ("limits-swapped", lambda md: {**md, META_ROBOT: {**md[META_ROBOT], "lower": 1.0, "upper": -1.0}},
     [META_ROBOT, "swapped"]),
    ("limits-nan", lambda md: {**md, META_ROBOT: {**md[META_ROBOT], "upper": float("nan")}}, [META_ROBOT, "upper"]),
])
def test_2_3_bad_metadata_is_one_line_naming_the_field(tmp_path, case, edit, needles):
    bad = rebuild(DELTA, tmp_path / f"{case}.mcap", meta=lambda md: list(edit(md).items()))
    if case == "model-nan":
        one_line_error(run_cli("calibrate", bad, "--out", tmp_path / "c"), str(bad), *needles)
    error_in_process(bad, tmp_path / "c", str(bad), *needles, calibrate=True)
    error_in_process(bad, tmp_path / "o", str(bad), *needles)


def test_2_swapped_serial_arm_limits_are_refused(tmp_path):
    def edit(md):
        robot = json.loads(json.dumps(md[META_ROBOT]))
        robot["joints"][1]["lower"], robot["joints"][1]["upper"] = robot["joints"][1]["upper"], robot["joints"][1]["lower"]
        return list({**md, META_ROBOT: robot}.items())

    bad = rebuild(SCANNER, tmp_path / "swapped.mcap", meta=edit)
    error_in_process(bad, tmp_path / "c", str(bad), "joints[1]", "swapped", calibrate=True)


def test_2_hostile_topics_and_face_ids(tmp_path):
    """NUL and 300-byte topics become safe, distinct file names; a face id with `$…$` renders."""
    nul, long_topic = "/evil\x00/../../x", "/" + "t" * 300
    extra = [(nul, 1, b'{"timestamp_ns":1}'), (long_topic, 2, b'{"timestamp_ns":2}')]
    rec = rebuild(DELTA, tmp_path / "topics.mcap", extra=[(t, lt + 1_700_000_000_000_000_000, d) for t, lt, d in extra])
    proc = ingest_validate(rec, tmp_path / "o")
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    chans = json.loads((tmp_path / "o/ingest/recording.json").read_text())["channels"]
    files = [chans[nul]["file"], chans[long_topic]["file"]]
    assert all((tmp_path / "o/ingest" / f).is_file() and "\x00" not in f and "/" not in f and len(f) < 120
               for f in files)

    from pipeline.report.plots import RC, _fig, _svg
    from matplotlib import rc_context

    with rc_context(RC):
        fig, ax = _fig(3, 2)
        ax[0, 0].set_xticks([0, 1], ["$\\frac{1}{$", "face $x^{$"])
        svg = _svg(fig)  # raised ValueError (mathtext) before
    assert "frac" in svg


def test_2_diagnose_on_a_fixture_without_faces(tmp_path):
    bad = rebuild(ARC, tmp_path / "nofaces.mcap",
                  meta=lambda md: list({**md, META_FIXTURE: {**md[META_FIXTURE], "faces": []}}.items()),
                  msg=lambda t, i, d: d if t != "/robot/joint_state" or i < 40 else None)
    one_line_error(run_cli("diagnose", bad, "--out", tmp_path / "d"), str(bad), META_FIXTURE, "record")


def test_2_read_only_output_folder(tmp_path):
    if os.geteuid() == 0:  # root ignores folder permissions; sysfs refuses even root
        ro = Path("/sys/kernel")
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
    line = one_line_error(ingest_validate(DELTA, ro / "robocal-run"), "cannot write", "PermissionError")
    assert str(ro) in line
    one_line_error(run_cli("calibrate", DELTA, "--out", ro / "robocal-cal"), str(ro), "cannot write")


def test_2_run_never_says_pass_after_a_stage_stopped(tmp_path, monkeypatch):
    bad = rebuild(DELTA, tmp_path / "bad.mcap", msg=edit_json("/tracker/point", 3, lambda m: {**m, "point": "x"}))
    out = tmp_path / "o"
    proc = run_cli("run", bad, "--out", out, "--stages", "ingest,validate,identify")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert not any(ln.split()[1:2] == ["pass"] for ln in proc.stderr.splitlines() if "status" in ln), proc.stderr
    assert json.loads((out / "results.json").read_text())["summary"]["status"] == "fail"
    # a stage that crashes after others passed: results.json says fail, with the reason
    import pipeline.stages.identify as identify
    from pipeline.stages.runner import run_pipeline

    def crash(*a, **k):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(identify, "run", crash)
    with pytest.raises(ZeroDivisionError):
        run_pipeline(DELTA, tmp_path / "crash", stages=["ingest", "validate", "identify"])
    s = json.loads((tmp_path / "crash" / "results.json").read_text())["summary"]
    assert s["status"] == "fail" and "identify" in s["error"] and "boom" in s["error"]


# ----- 3. wrong successes ---------------------------------------------------------------------
def test_3_delta_joint_angle_beyond_limits_fails_validate(tmp_path):
    def huge(m):
        return {**m, "joint_positions": [2.0 ** 70] + m["joint_positions"][1:]}

    bad = rebuild(DELTA, tmp_path / "huge.mcap", msg=edit_json("/tracker/point", 4, huge))
    line = error_in_process(bad, tmp_path / "o", "joint_limits")
    assert "record" in line and "4" in line and str(bad) in line


def test_3_a_second_robot_model_record_is_refused(tmp_path):
    def dup(md):
        other = {**md[META_ROBOT], "l1": md[META_ROBOT]["l1"] * 1.1}
        return list(md.items()) + [(META_ROBOT, other)]

    bad = rebuild(DELTA, tmp_path / "dup.mcap", meta=dup)
    with pytest.raises(RobocalError, match="appears twice"):
        read_recording(bad)
    one_line_error(run_cli("calibrate", bad, "--out", tmp_path / "c"), str(bad), META_ROBOT, "twice")


def _emptied(c):
    c.compression = ""
    return c


def test_3_emptied_compression_is_lost_with_a_warning_and_no_pass(tmp_path):
    src = rebuild(DELTA, tmp_path / "chunks.mcap", chunk_size=4096)  # several chunks
    buf = src.read_bytes()
    n = len(chunk_offsets(buf))
    assert n >= 4
    bad = tmp_path / "emptied.mcap"
    bad.write_bytes(replace_chunk(buf, 1, _emptied))
    full, rec = read_recording(src), read_recording(bad)
    lost = sum(map(len, full.messages.raw.values())) - sum(map(len, rec.messages.raw.values()))
    assert 0 < lost < 60  # one chunk's worth, the later chunks kept
    assert rec.messages.raw["/tracker/point"][-1] == full.messages.raw["/tracker/point"][-1]
    assert any("lost" in w or "skipped" in w for w in rec.warnings), rec.warnings
    proc = run_cli("run", bad, "--out", tmp_path / "o", "--stages", "ingest,validate,identify")
    res = json.loads((tmp_path / "o/results.json").read_text())
    assert res["summary"]["status"] != "pass" and res["warnings"], (proc.stderr[-2000:], res["summary"])


@pytest.mark.parametrize("summary_intact", [True, False])
def test_3_one_damaged_chunk_keeps_every_intact_chunk_after_it(tmp_path, summary_intact):
    buf = ARC.read_bytes()
    offs = chunk_offsets(buf)
    k = 5
    if summary_intact:  # garbage in place: sizes and the summary's index hold
        b = bytearray(buf)
        b[offs[k] + 200:offs[k] + 400] = bytes(200)
        damaged = bytes(b)
    else:  # framing of the chunk broken and offsets shifted: found by its neighbours' framing
        damaged = buf[:offs[k] + 1] + b"\xff" * 8 + buf[offs[k] + 9 + 50:]
    bad = tmp_path / "chunk.mcap"
    bad.write_bytes(damaged)
    full, rec = read_recording(ARC), read_recording(bad)
    js_full, js = full.messages.raw["/robot/joint_state"], rec.messages.raw["/robot/joint_state"]
    assert js[-1] == js_full[-1] and 0 < len(js_full) - len(js) < len(js_full) / len(offs) * 2
    assert rec.messages.raw["/touch/contact"][-1] == full.messages.raw["/touch/contact"][-1]
    assert rec.warnings and any(f"byte {offs[k]}" in w for w in rec.warnings), rec.warnings


# ----- 4, 5. run folders: never delete a user's files; one run at a time -------------------------------
def test_4_a_users_folder_is_never_emptied(tmp_path):
    out = tmp_path / "mine"
    (out / "ingest").mkdir(parents=True)
    (out / "ingest" / "thesis.tex").write_text("three years")
    (out / "notes.txt").write_text("keep")
    one_line_error(ingest_validate(DELTA, out), str(out), "not written by robocal")
    assert (out / "ingest" / "thesis.tex").read_text() == "three years" and (out / "notes.txt").read_text() == "keep"
    assert sorted(p.name for p in out.iterdir()) == ["ingest", "notes.txt"]  # nothing written either


def test_4_a_foreign_stage_folder_inside_a_run_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    assert ingest_validate(DELTA, out).returncode == 0
    import shutil
    shutil.rmtree(out / "validate")
    (out / "validate").mkdir()
    (out / "validate" / "mine.txt").write_text("keep")
    one_line_error(ingest_validate(DELTA, out), str(out / "validate"), "not written by robocal")
    assert (out / "validate" / "mine.txt").read_text() == "keep"
    # robocal's own folders are replaced as before (an existing empty folder is adopted) ...
    from pipeline.stages.runner import run_pipeline

    (tmp_path / "empty").mkdir()
    run_pipeline(DELTA, tmp_path / "empty", stages=["ingest", "validate"])
    # ... and so is a run folder written before the markers (nothing but stage folders with stage.json)
    for m in (tmp_path / "empty").rglob(".robocal-*"):
        m.unlink()
    run_pipeline(DELTA, tmp_path / "empty", stages=["ingest", "validate"], force=True)
    assert (tmp_path / "empty" / ".robocal-run").is_file()


def test_5_concurrent_runs_on_one_folder_take_turns(tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    procs = [subprocess.Popen([ROBOCAL, "run", str(DELTA), "--out", str(out), "--stages", "ingest,validate",
                               "--force"], stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    assert not any("Traceback" in e for e in errs)
    assert json.loads((out / "results.json").read_text())["summary"]["status"] == "pass"


def test_5_a_held_lock_names_its_process(tmp_path):
    from pipeline.stages.runfolder import locked

    out = tmp_path / "run"
    with locked(out):
        env = {**os.environ, "ROBOCAL_LOCK_TIMEOUT_S": "0.5"}
        proc = subprocess.run([ROBOCAL, "run", str(DELTA), "--out", str(out), "--stages", "ingest"],
                              capture_output=True, text=True, env=env, timeout=120)
    one_line_error(proc, str(out), f"pid {os.getpid()}")


# ----- 6. channel names cannot collide ----------------------------------------------------------
def test_6_topics_cannot_collide_with_each_other_or_ingests_files(tmp_path):
    t0 = 1_700_000_000_000_000_000
    decoys = [("/tracker_point", t0 + 1, b'{"timestamp_ns":1,"decoy":true}')] + [
        (t, t0 + 2 + i, b'{"timestamp_ns":2,"decoy":true}') for i, t in enumerate(("/encoder", "/messages", "/measurements"))]
    rec = rebuild(DELTA, tmp_path / "decoy.mcap", extra=decoys)
    out = tmp_path / "o"
    proc = ingest_validate(rec, out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    chans = json.loads((out / "ingest/recording.json").read_text())["channels"]
    files = [c["file"] for c in chans.values()]
    assert len(set(files)) == len(files) and not {"encoder.parquet", "messages.parquet", "measurements.parquet",
                                                  "recording.json"} & set(files)
    import pyarrow.parquet as pq
    assert pq.read_table(out / "ingest" / chans["/tracker/point"]["file"]).num_rows == 27
    assert pq.read_table(out / "ingest/encoder.parquet").num_rows > 100
    assert "decoy" not in pq.read_table(out / "ingest/measurements.parquet").column_names


# ----- 8. validate names the file; the recording's registered schemas are checked ----------------
@pytest.mark.parametrize("case,spec", [
    ("garbage-schema", {"schema_data": b"\x00garbage"}),
    ("other-schema", {"schema_name": "robocal.TouchContact"}),
    ("cbor", {"message_encoding": "cbor"}),
])
def test_8_registered_schema_and_encoding_are_checked(tmp_path, case, spec):
    bad = rebuild(DELTA, tmp_path / f"{case}.mcap", channel=lambda t: spec if t == "/tracker/point" else {})
    error_in_process(bad, tmp_path / "o", str(bad), "/tracker/point")
    error_in_process(bad, tmp_path / "c", str(bad), "/tracker/point", calibrate=True)


def test_8_every_validate_message_names_the_file(tmp_path):
    src = rebuild(DELTA, tmp_path / "dups.mcap",
                  extra=[("/tracker/point", 1_700_000_000_000_000_000 + 7, b'{"timestamp_ns":5,"joint_positions":[0,0,0],"point":[0,0,0],"extra":1}')])
    out = tmp_path / "o"
    from pipeline.stages.runner import run_pipeline
    run_pipeline(src, out, stages=["ingest", "validate"])
    checks = json.loads((out / "validate/validate.json").read_text())["checks"]
    bad = [c for c in checks if c["status"] != "pass"]
    assert bad and all(c["message"].startswith(str(src.resolve())) for c in bad), bad
    assert np.all([c["channel"] for c in bad])
