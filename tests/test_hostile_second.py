"""Hostile input, second pass: CSV tables, URDFs, campaign and target files, run folders, ROS 2 bags,
recordings whose measurement topic is missing or whose times run backwards.  Each test failed (a
traceback, a hang, silent acceptance or deleted user files) on the code before its fix."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from hostile_support import BUNDLED, rebuild
from pipeline.errors import RobocalError
from test_hostile_input import one_line_error
from test_urdf_import import ARM, GOOD, import_point, write_csv, write_urdf

DELTA, ARC = BUNDLED["delta-tracker"], BUNDLED["arc-welder-touch"]


def csv_error(tmp_path: Path, text: str | bytes, *needles: str, urdf: Path | None = None) -> str:
    """The one-line error `robocal import csv` gives for this table (in process: what the CLI prints)."""
    from pipeline.importers.csv_table import CsvSpec, read_table
    from pipeline.models import urdf as urdf_mod

    p = tmp_path / "data.csv"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    desc = urdf_mod.read(urdf or write_urdf(tmp_path), "base", "tip")
    with pytest.raises(RobocalError) as e:
        read_table([p], desc, CsvSpec(measure="point"))
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg
    for n in needles:
        assert n in msg, (n, msg)
    return msg


# ----- CSV tables ----------------------------------------------------------------------------
@pytest.mark.parametrize("text,needles", [
    ("x,y,z,j2,j1,j1\n0.1,0.2,0.3,0.1,0.2,0.2\n", ["'j1'", "twice"]),
    (b"x,y,z,j2,j1\n0.1,0.2,0.3,0.1,0.2\n0.2,0.1,0.3,0.3,0.4\xe9\n", ["line 3", "0xe9", "UTF-8"]),
    (b"x,y,z,j2,j1,note\n0.1,0.2,0.3,0.1,0.2,caf\xe9\n", ["line 2", "UTF-8"]),
    (b"x,y,z,j2,j1\xe9\n0.1,0.2,0.3,0.1,0.2\n", ["line 1", "UTF-8"]),
    (GOOD + "0.2,1e308,0.3,0.3,0.4\n", ["row 4", "'y'", "1e+308"]),
    (GOOD + "0.2,-1e7,0.3,0.3,0.4\n", ["row 4", "'y'"]),
    (GOOD + "0.2,0_5,0.3,0.3,0.4\n", ["row 4", "'y'", "'0_5'", "not a number"]),
    (GOOD + "0.2,0.1,0.3,0_1,0.4\n", ["row 4", "'j2'", "not a number"]),
    (GOOD + "0.2,0.1,0.3,0.1,0.4,7\n", ["line 4", "6 fields"]),
])
def test_bad_csv_is_one_line_naming_file_and_row(tmp_path, text, needles):
    csv_error(tmp_path, text, *needles)


def test_bad_csv_through_the_command_line(tmp_path):
    csv = write_csv(tmp_path, "x,y,z,j2,j1,j1\n0.1,0.2,0.3,0.1,0.2,0.2\n")
    one_line_error(import_point(tmp_path, write_urdf(tmp_path), csv), str(csv), "'j1'", "twice")
    assert not (tmp_path / "out.mcap").exists()


def test_a_wide_csv_is_read_in_bounded_memory(tmp_path):
    """100 000 columns (16 MB): only the columns used are kept (pyarrow needed 1.84 GB)."""
    n = 100_000
    p = tmp_path / "wide.csv"
    with open(p, "w") as f:
        f.write(",".join(["x", "y", "z", "j1", "j2"] + [f"c{i}" for i in range(n - 5)]) + "\n")
        for r in range(40):
            f.write(",".join([f"0.{r % 9 + 1}", "0.2", "0.3", "0.1", "0.2"] + ["1.5"] * (n - 5)) + "\n")
    code = ("from pipeline.importers.csv_table import CsvSpec, read_table; from pipeline.models import urdf;"
            f"t, _ = read_table([{str(p)!r}], urdf.read({str(write_urdf(tmp_path))!r}, 'base', 'tip'), "
            "CsvSpec(measure='point')); print(t['position'].shape, "
            "[ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')][0])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    shape, rss_kb = out.stdout.rsplit(" ", 1)
    assert shape == "(40, 3)" and int(rss_kb) < 500_000, out.stdout


def test_a_good_csv_reads_the_same_numbers_as_numpy(tmp_path):
    """The strict reader still reads every decimal spelling a spreadsheet writes, to the bit."""
    from pipeline.importers.csv_table import CsvSpec, read_table
    from pipeline.models import urdf as urdf_mod

    vals = np.array([[0.1, -2e-3, 3.0, 0.25, -1.5], [1e-7, 0.3333333333333333, -0.0, 2.5e0, 0.1]])
    text = "x,y,z,j2,j1\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in vals) + "\n" + " .5 ,+1,-.25E+1,1,2\n"
    p = write_csv(tmp_path, "\ufeff" + text)
    t, _ = read_table([p], urdf_mod.read(write_urdf(tmp_path), "base", "tip"), CsvSpec(measure="point"))
    ref = np.loadtxt(p, delimiter=",", skiprows=1, encoding="utf-8-sig")
    assert np.array_equal(t["position"], ref[:, :3]) and np.array_equal(t["joint_positions"], ref[:, [4, 3]])


def test_bad_targets_csv_for_compensate(tmp_path):
    from pipeline.compensate.program import read_targets

    for text, needles in [("x,y,z,x\n1,2,3,4\n", ["'x'", "twice"]), (b"x,y,z\n1,2,3\xe9\n", ["line 2", "UTF-8"]),
                          ("x,y,z\n1,2,1e308\n", ["row 1", "'z'"]), ("x,y,z\n1,2_0,3\n", ["row 1", "not a number"])]:
        p = tmp_path / "targets.csv"
        p.write_bytes(text if isinstance(text, bytes) else text.encode())
        with pytest.raises(RobocalError) as e:
            read_targets(p, ["j1"])
        assert "\n" not in str(e.value) and str(p) in str(e.value)
        assert all(n in str(e.value) for n in needles), (needles, str(e.value))


def test_a_run_folder_whose_fit_is_not_json(tmp_path):
    run = tmp_path / "run"
    (run / "identify").mkdir(parents=True)
    fit = run / "identify" / "fit.json"
    targets = write_csv(tmp_path, "x,y,z\n0.1,0.2,0.3\n")
    for body in ("{", '{"names": 3}', "[1]"):
        fit.write_text(body)
        before = fit.read_bytes()
        proc = run_cli("compensate", run, "--targets", targets, "--out", tmp_path / "prog.csv")
        one_line_error(proc, str(fit), "not robocal's fit")
        assert fit.read_bytes() == before and not (tmp_path / "prog.csv").exists()


# ----- URDFs ---------------------------------------------------------------------------------
@pytest.mark.parametrize("edit,needles", [
    (lambda t: t.replace('<joint name="j2"', '<joint name="j1"'), ["joint 'j1'", "defined twice"]),
    (lambda t: t.replace('<link name="l2"/>', '<link name="l2"/><link name="l1"/>'), ["link 'l1'", "defined twice"]),
    (lambda t: t.replace('xyz="0.4 0 0"', 'xyz="1e308 0 0"'), ["joint 'j2'", "origin", "1e308"]),
    (lambda t: t.replace('rpy="1.5707963 0 0"', 'rpy="1.5707963 -1e308 0"'), ["joint 'j2'", "rpy"]),
    (lambda t: t.replace('<origin xyz="0 0 0.3"', '<origin xyz="0 0 1e7"'), ["joint 'j1'", "origin"]),
])
def test_bad_urdf_second_pass_is_one_line(tmp_path, edit, needles):
    p = tmp_path / "bad.urdf"
    p.write_text(edit(ARM.format(j2type="revolute", tip_parent="l2")))
    from pipeline.models import urdf as urdf_mod

    with pytest.raises(RobocalError) as e:
        urdf_mod.read(p, "base", "tip")
    assert "\n" not in str(e.value) and str(p) in str(e.value)
    assert all(n in str(e.value) for n in needles), (needles, str(e.value))


# ----- campaign files, counts, figures ---------------------------------------------------------
@pytest.fixture(scope="module")
def touch_plan(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("plan") / "plan.json"
    proc = run_cli("plan", "arc-welder", "--candidates", "80", "--select", "30", "--out", out)
    assert proc.returncode == 0, proc.stderr
    return out


def test_a_campaign_nested_100000_deep_is_one_line(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text('{"a":' * 100_000 + "1" + "}" * 100_000)
    one_line_error(run_cli("simulate", "arc-welder", "--campaign", deep, "--out", tmp_path / "sim.mcap"),
                   str(deep), "nested")
    assert not (tmp_path / "sim.mcap").exists()
    from pipeline.plan.campaign import load_document

    for depth in (900, 5000):  # under and over the recursion limit: the schema check recurses too
        deep.write_text('{"measurements":' * depth + "1" + "}" * depth)
        with pytest.raises(RobocalError) as e:
            load_document(deep)
        assert str(deep) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("field,value", [("rate_hz", 1e308), ("dwell_s", 1e300), ("search_speed_m_s", 1e-300)])
def test_a_campaign_whose_controller_would_run_forever(tmp_path, touch_plan, field, value):
    from pipeline.plan import campaign

    doc = json.loads(touch_plan.read_text())
    doc["controller"][field] = value
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(RobocalError) as e:
        campaign.read(bad, "arc-welder")
    assert str(bad) in str(e.value) and "controller" in str(e.value) and "\n" not in str(e.value)
    assert campaign.read(touch_plan, "arc-welder").campaign.rate_hz == 250.0


@pytest.mark.parametrize("args,needles", [
    (["simulate", "arc-welder", "--contacts", str(2 ** 70)], ["--contacts", str(2 ** 70)]),
    (["simulate", "arc-welder", "--dwell-s", "1e308"], ["--dwell-s"]),
    (["simulate", "delta-tracker", "--points", str(2 ** 70)], ["--points"]),
    (["plan", "arc-welder", "--candidates", str(2 ** 70)], ["--candidates"]),
])
def test_absurd_counts_are_one_line(tmp_path, args, needles):
    one_line_error(run_cli(*args, "--out", tmp_path / "out"), *needles)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("sigma", [[1e-3, 1e-3 + 2e-19, 1e-3], [1e-3] * 3, [-1e300, 1e300], [np.nan, 1e-3]])
def test_report_histograms_of_a_few_equal_values(sigma):
    """A 3-row table's predicted accuracies can be equal to the last bit: one bin, not 'Too many bins'."""
    from pipeline.report.accuracy import histograms
    from pipeline.report.plots import point_sigma

    v = np.array(sigma)
    with np.errstate(all="ignore"):
        assert point_sigma(np.arange(v.size), v).lstrip().startswith("<")
        assert "<svg" in histograms(v, v, 1e-4)


# ----- recordings: the measurement topic missing, times running backwards -----------------------
@pytest.mark.parametrize("topic", ["/../../x", "/" + "t" * 300, "/mesure/point\u00e9\u2603", "/tracker/po\x00int",
                                   "/touch/contact", "/tracker/point\n/fake"])
def test_a_renamed_measurement_topic_is_one_line(tmp_path, topic):
    from test_hostile_input import error_in_process

    bad = rebuild(DELTA, tmp_path / "renamed.mcap",
                  channel=lambda t: {"topic": topic} if t == "/tracker/point" else {})
    needles = ["/touch/contact", "registered schema"] if topic == "/touch/contact" else ["/tracker/point",
                                                                                          "missing or empty"]
    error_in_process(bad, tmp_path / "o", str(bad), *needles)


def test_campaign_system_naming_another_system_is_one_line(tmp_path):
    from pipeline.recording.schemas import META_CAMPAIGN
    from test_hostile_input import error_in_process

    bad = rebuild(DELTA, tmp_path / "other-system.mcap",
                  meta=lambda md: list({**md, META_CAMPAIGN: {**md[META_CAMPAIGN], "system": "arc-welder"}}.items()))
    error_in_process(bad, tmp_path / "o", str(bad), "missing or empty")


@pytest.mark.parametrize("case,fn,needles", [
    ("negative", lambda m: {**m, "timestamp_ns": -5}, ["record 3", "negative"]),
    ("backwards", lambda m: {**m, "timestamp_ns": m["timestamp_ns"] - 10 ** 12}, ["record 3", "backwards"]),
])
def test_a_contact_time_that_is_negative_or_runs_backwards(tmp_path, case, fn, needles):
    """Named at ingest, before diagnose fitted a drift against it (SVD did not converge)."""
    from hostile_support import edit_json
    from test_hostile_input import error_in_process

    bad = rebuild(ARC, tmp_path / f"{case}.mcap", msg=edit_json("/touch/contact", 3, fn))
    error_in_process(bad, tmp_path / "o", str(bad), "/touch/contact", *needles)


# ----- run folders: never delete what robocal did not write -------------------------------------
def _tree(d: Path) -> dict[str, bytes]:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_a_users_folder_that_looks_like_an_old_run_is_not_emptied(tmp_path):
    """ingest/stage.json and results.json beside the user's own files: not an old run folder."""
    from pipeline.stages.runner import run_pipeline

    out = tmp_path / "mine"
    (out / "ingest").mkdir(parents=True)
    (out / "ingest" / "stage.json").write_text('{"stage": "ingest", "outputs": {}}')
    (out / "ingest" / "thesis.tex").write_text("three years")
    (out / "results.json").write_text("{}")
    before = _tree(out)
    one_line_error(run_cli("run", DELTA, "--out", out, "--stages", "ingest,validate"), "not written by robocal")
    with pytest.raises(RobocalError):
        run_pipeline(DELTA, out, stages=["ingest"], force=True)
    assert _tree(out) == before  # nothing deleted, nothing written


def test_force_never_deletes_a_users_file_inside_robocals_stage_folder(tmp_path):
    from pipeline.stages.runner import run_pipeline

    out = tmp_path / "run"
    run_pipeline(DELTA, out, stages=["ingest", "validate"])
    (out / "ingest" / "my-notes.txt").write_text("keep")
    (out / "validate" / "sub").mkdir()
    (out / "validate" / "sub" / "plot.png").write_bytes(b"\x89PNG mine")
    with pytest.raises(RobocalError) as e:
        run_pipeline(DELTA, out, stages=["ingest", "validate"], force=True)
    assert "my-notes.txt" in str(e.value) and "not written by robocal" in str(e.value)
    assert (out / "ingest" / "my-notes.txt").read_text() == "keep"
    (out / "ingest" / "my-notes.txt").unlink()
    with pytest.raises(RobocalError) as e:
        run_pipeline(DELTA, out, stages=["ingest", "validate"], force=True)
    assert "plot.png" in str(e.value)
    assert (out / "validate" / "sub" / "plot.png").read_bytes() == b"\x89PNG mine"
    (out / "validate" / "sub" / "plot.png").unlink()
    (out / "validate" / "sub").rmdir()
    # robocal's own files are still replaced: forced, a stopped stage, and a run folder from before manifests
    run_pipeline(DELTA, out, stages=["ingest", "validate"], force=True)
    for m in out.rglob(".robocal-*"):
        m.unlink()
    run_pipeline(DELTA, out, stages=["ingest", "validate"], force=True)
    assert sorted(p.name for p in (out / "ingest").iterdir()) == sorted(
        [".robocal-stage", "encoder.parquet", "measurements.parquet", "messages.parquet", "recording.json",
         "stage.json", "tracker_point.parquet"])


def test_a_stage_that_stopped_records_what_it_wrote(tmp_path):
    from pipeline.stages.runner import run_pipeline

    bad = rebuild(DELTA, tmp_path / "neg.mcap",
                  msg=lambda t, i, d: d.replace(b'"timestamp_ns":', b'"timestamp_ns":-', 1) if (
                      t == "/tracker/point" and i == 2) else d)
    out = tmp_path / "run"
    with pytest.raises(RobocalError):
        run_pipeline(bad, out, stages=["ingest", "validate"])
    written = json.loads((out / "validate" / ".robocal-stage").read_text())["files"]
    (out / "validate" / "mine.txt").write_text("keep")
    with pytest.raises(RobocalError) as e:
        run_pipeline(bad, out, stages=["ingest", "validate"], force=True)
    assert "mine.txt" in str(e.value) and (out / "validate" / "mine.txt").read_text() == "keep"
    assert set(written) <= {p.name for p in (out / "validate").iterdir()}


# ----- ROS 2 bags cut short ----------------------------------------------------------------------
@pytest.fixture
def r6(tmp_path):
    from pipeline.models import urdf
    from test_urdf_simulate import R6T

    p = tmp_path / "r6.urdf"
    p.write_text(R6T)
    return p, urdf.parse(R6T, "b", "tcp")


def _cut_bag(tmp_path: Path, desc, frac: float, keep_metadata: bool = True, n: int = 40) -> tuple[Path, dict]:
    """A bag written by rosbags' own writer, its MCAP storage file then cut to `frac` of its bytes."""
    from pipeline.simulate.ros2_bag import simulate_bag

    bag = tmp_path / "bag"
    truth = simulate_bag(bag, desc, n=n, seed=4)
    f = truth["storage"]
    f.write_bytes(f.read_bytes()[: int(f.stat().st_size * frac)])
    if not keep_metadata:  # the recorder was killed before it wrote metadata.yaml
        (bag / "metadata.yaml").unlink()
    return bag, truth


def test_a_truncated_bag_is_salvaged_with_a_warning_naming_what_was_lost(tmp_path, r6):
    from pipeline.ros2.points import read_bag
    from pipeline.recording.reader import read_recording
    from pipeline.simulate.ros2_bag import simulate_bag

    upath, desc = r6
    whole, _ = read_bag(simulate_bag(tmp_path / "whole", desc, n=40, seed=4)["storage"].parent, desc)
    bag, _ = _cut_bag(tmp_path, desc, 0.6)
    out = tmp_path / "rec.mcap"
    proc = run_cli("import", "ros2", bag, "--urdf", upath, "--root", "b", "--tip", "tcp", "--out", out)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert "damaged ROS 2 bag" in proc.stderr and "topic /tracker/point:" in proc.stderr and " of 40 messages lost" in proc.stderr
    got = np.asarray(read_recording(out).metadata["robocal.campaign"]["ros2"]["measurement_records"])
    table, extras = read_bag(bag, desc)
    assert 0 < len(got) < 40 and np.array_equal(table["position"], whole["position"][: len(table["position"])])
    assert any("messages lost" in w for w in extras["import_warnings"])
    from pipeline.stages.runner import run_pipeline

    ingest = run_pipeline(out, tmp_path / "run", stages=["ingest"])[0]
    assert ingest.summary["status"] == "warn" and any("messages lost" in w for w in ingest.summary["warnings"])


def test_a_bag_whose_recorder_was_killed_is_salvaged(tmp_path, r6):
    """No metadata.yaml and no MCAP footer: read what is there, say the loss is unknown."""
    from pipeline.ros2.kind import ros2_kind
    from pipeline.ros2.points import read_bag

    _, desc = r6
    bag, _ = _cut_bag(tmp_path, desc, 0.8, keep_metadata=False)
    assert ros2_kind(bag) == "folder"
    table, extras = read_bag(bag, desc)
    assert 0 < len(table["position"]) < 40
    assert any("lost is unknown" in w for w in extras["import_warnings"])
    assert any("before the MCAP footer" in w for w in extras["import_warnings"])


def test_a_bag_with_nothing_readable_is_one_line(tmp_path, r6):
    upath, desc = r6
    bag, _ = _cut_bag(tmp_path, desc, 0.1)
    proc = run_cli("import", "ros2", bag, "--urdf", upath, "--root", "b", "--tip", "tcp", "--out", tmp_path / "r.mcap")
    one_line_error(proc, str(bag), "no message could be salvaged")
    assert not (tmp_path / "r.mcap").exists()
