"""`robocal import csv`: measurement tables of any URDF robot → a self-contained recording."""

from __future__ import annotations

from pathlib import Path
from typing import Literal, Optional

import typer
from rich.markup import escape

from pipeline.cli import IMPORT, app, err, force_option

import_app = typer.Typer(help="Bring measurements of any URDF robot in: CSV tables (and ROS 2 bags) → a recording.",
                         no_args_is_help=True)
app.add_typer(import_app, name="import", rich_help_panel=IMPORT)


def _cols(s: str) -> tuple[str, ...]:
    return tuple(c.strip() for c in s.split(",") if c.strip())


def parse_plane(spec: str) -> tuple[str, dict]:
    """``NAME:NX,NY,NZ:OFFSET`` (OFFSET a column name or a number, m) → (name, plane)."""
    from pipeline.errors import RobocalError

    parts = spec.split(":")
    if len(parts) != 3:
        raise RobocalError(f"--plane {spec!r}: expected NAME:NX,NY,NZ:OFFSET (OFFSET a column or a number in m)")
    name, normal, off = parts
    try:
        n = [float(v) for v in normal.split(",")]
        assert len(n) == 3 and any(n)
    except (ValueError, AssertionError):
        raise RobocalError(f"--plane {spec!r}: normal {normal!r} is not three numbers") from None
    try:
        offset: float | str = float(off)
    except ValueError:
        offset = off
    return name, {"normal": n, "offset": offset}


@import_app.command("csv")
def import_csv(
    files: list[Path] = typer.Argument(..., help="CSV file(s); rows of several files are concatenated."),
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF); meshes are not needed."),
    root: str = typer.Option(..., "--root", help="Root link of the calibrated chain."),
    tip: list[str] = typer.Option(..., "--tip", help="Tip link of the calibrated chain; a robot measured at several "
                                  "links: LINK=X,Y,Z (its position columns), repeatable (point)."),
    coupled: list[str] = typer.Option([], "--coupled", help="A joint driven by others, not in the CSV: "
                                      "JOINT=EXPR, e.g. torso_3=-torso_1-torso_2, lift=0.01[m/rad]*j1 (a factor "
                                      "between a prismatic and a revolute joint carries its unit; repeatable)."),
    coupling_wins: bool = typer.Option(False, "--coupling-wins", help="A --coupled joint that has its own column: "
                                       "the coupling replaces the column (without this that is an error)."),
    measure: Literal["point", "pose", "plane", "coincidence", "effort"] = typer.Option(..., "--measure", help="point | pose | plane | coincidence | effort (joint "
                                "position / velocity / effort logs for dynamics)."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    joint_units: Literal["rad", "deg"] = typer.Option("rad", "--joint-units", help="Revolute joint columns in rad or deg."),
    length_units: Literal["m", "mm"] = typer.Option("m", "--length-units", help="Positions and prismatic joints in m or mm."),
    columns: str = typer.Option("", "--columns", help="Column names for files without a header, comma-separated."),
    position: str = typer.Option("", "--position-cols", help="Position columns (point, pose; default x,y,z; not "
                                 "with --tip LINK=X,Y,Z)."),
    target: list[str] = typer.Option([], "--target-cols", help="Further targets' x,y,z columns (point), repeatable."),
    orientation: str = typer.Option("", "--orientation-cols", help="Orientation columns (pose)."),
    orientation_kind: Literal["rpy", "quat"] = typer.Option("rpy", "--orientation", help="rpy (URDF roll,pitch,yaw, rad) or quat (x,y,z,w)."),
    plane: list[str] = typer.Option([], "--plane", help="Plane of a file: STEM:NX,NY,NZ:OFFSET (repeatable)."),
    unknown_planes: bool = typer.Option(False, "--unknown-planes", help="Estimate the planes' tilt and offset."),
    group_from: Literal["file", "parent/file"] = typer.Option("file", "--group-from", help="Coincidence group of a row: file or parent/file."),
    distance: list[str] = typer.Option([], "--distance", help="Known distance between two groups: A:B:METRES."),
    sigma_m: Optional[float] = typer.Option(None, "--sigma-m", help="The instrument's position uncertainty (1σ per "
                                            "axis), m: residuals far above it fail the calibration naming the likely "
                                            "cause (units, columns, chain); pose: also the weighting (default 1 mm)."),
    sigma_rad: float = typer.Option(1e-3, "--sigma-rad", help="Pose: orientation uncertainty, rad."),
    robot_id: str = typer.Option("", "--robot-id", help="Robot identity (name or serial) stored in the campaign."),
    instrument: str = typer.Option("", "--instrument", help="Instrument identity (tracker serial, mocap room) stored "
                                                            "in the campaign: recordings sharing a registration "
                                                            "must name the same (robocal evaluate)."),
    force: bool = force_option(),
    velocity_csv: Optional[Path] = typer.Option(None, "--velocity-csv", help="Effort: the joint velocity table "
                                                "(columns t and JOINT_velocity), when not in the first file."),
    effort_csv: Optional[Path] = typer.Option(None, "--effort-csv", help="Effort: the joint effort table (columns t "
                                              "and JOINT_effort), when not in the first file."),
    effort_scale: list[str] = typer.Option([], "--effort-scale", help="Effort: N·m (N) per raw effort unit, "
                                           "JOINT=K,… (gear ratio × motor constant); repeatable."),
    effort_offset: list[str] = typer.Option([], "--effort-offset", help="Effort: N·m (N) added after scaling, "
                                            "JOINT=C,…; C = weight: g × the mass the joint carries (a lift)."),
    effort_mix: list[str] = typer.Option([], "--effort-mix", help="Effort: the raw efforts a joint's torque "
                                         "combines, JOINT=EXPR (a differential wrist: j6=-j6+j7); repeatable."),
    effort_joints: str = typer.Option("", "--effort-joints", help="Effort: the joints whose torque is fitted and "
                                      "scored, comma-separated (default: all)."),
    effort_units: Optional[Literal["Nm", "raw"]] = typer.Option(None, "--effort-units", help="Effort: Nm (efforts are joint "
                                               "torques) or raw (with --effort-scale); default raw with a scale, "
                                               "else unknown."),
    rows: str = typer.Option("", "--rows", help="Effort: keep data rows A:B (zero-based, B excluded)."),
    time_col: str = typer.Option("t", "--time-col", help="Effort: the time column (s)."),
    rate: Optional[float] = typer.Option(None, "--rate", help="Effort: the sample rate (Hz) of tables without a "
                                         "time column (row i at i / rate s)."),
    position_scale: list[str] = typer.Option([], "--position-scale", help="Effort: rad (m) per raw position unit, "
                                             "JOINT=K,… (motor-side angles through a reduction N: 1/N); repeatable."),
    position_offset: list[str] = typer.Option([], "--position-offset", help="Effort: rad (m) added after scaling, "
                                              "JOINT=C,… (e.g. -pi/2: the joint's zero)."),
    position_mix: list[str] = typer.Option([], "--position-mix", help="Effort: the raw positions a joint's angle "
                                           "combines before scaling, JOINT=EXPR (a coupled wrist: "
                                           "j6=j6-32/45*j5); repeatable."),
) -> None:
    """Map CSV columns to the URDF's joints (by header name) and write a recording `robocal run` calibrates."""
    from pipeline.errors import RobocalError
    from pipeline.recording.output import check_output, claim_output

    if measure == "effort":
        from pipeline.cli.import_effort import import_effort

        check_output(out, force=force)  # before any work: an existing recording only with --force
        return import_effort(files, urdf, root, tip, out, velocity_csv, effort_csv, effort_scale, effort_offset,
                             effort_mix, effort_joints, effort_units, rows, time_col, robot_id, force=force,
                             rate=rate, positions=(position_scale, position_offset, position_mix))
    if measure not in ("point", "pose", "plane", "coincidence"):
        raise RobocalError(f"--measure {measure!r}: expected point, pose, plane, coincidence or effort")
    if joint_units not in ("rad", "deg") or length_units not in ("m", "mm"):
        raise RobocalError("--joint-units takes rad or deg, --length-units m or mm")
    if sigma_m is not None and not (sigma_m > 0 and sigma_m < 1):
        raise RobocalError(f"--sigma-m {sigma_m!r}: expected the instrument's 1σ in m, 0 < σ < 1")
    if measure == "pose" and not orientation:
        raise RobocalError("--measure pose needs --orientation-cols")
    if out.exists() and out.resolve() in {f.resolve() for f in files}:
        raise RobocalError(f"{out}: --out is one of the input files")
    check_output(out, force=force)  # before any work: an existing recording only with --force
    if orientation_kind not in ("rpy", "quat"):
        raise RobocalError(f"--orientation {orientation_kind!r}: expected rpy or quat")
    tips = _tips(tip, measure, target)
    if tips and position:
        raise RobocalError(f"--position-cols {position!r} and --tip LINK=X,Y,Z cannot be combined: give each link's "
                           "columns with --tip")
    position = position or "x,y,z"
    _column_use(measure, tips, position, target, orientation, orientation_kind, plane, [])  # before the URDF is read
    from pipeline.importers.csv_table import CsvSpec, read_table
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.models import urdf as urdf_mod

    desc = urdf_mod.read(urdf, root, tip[0]) if tips is None and not coupled else _tree_desc(urdf, root, tips or
                                                                                            [(tip[0], None)], coupled)
    _column_use(measure, tips, position, target, orientation, orientation_kind, plane, desc.joint_names)
    if tips:
        position, target = ",".join(tips[0][1]), [",".join(c) for _, c in tips[1:]]
    planes = dict(parse_plane(p) for p in plane)
    for p in planes.values():
        p["known"] = not unknown_planes
    spec = CsvSpec(measure=measure, joint_units=joint_units, length_units=length_units, columns=_cols(columns),
                   position=_cols(position), targets=tuple(_cols(t) for t in target),
                   orientation=_cols(orientation), orientation_kind=orientation_kind, group_from=group_from,
                   planes=planes, coupled=tuple(_coupled_names(coupled)), coupling_wins=coupling_wins)
    table, extras = read_table(files, desc, spec)
    campaign = {**extras, "source_files": [str(f) for f in files], "robot_id": robot_id or desc.name}
    if instrument:
        campaign["instrument"] = instrument
    if coupled:
        from pipeline.models.coupling import parse_coupling

        campaign["coupled"] = {c: {"terms": t, "offset": o} for c, t, o in map(parse_coupling, coupled)}
    if measure == "pose":
        campaign |= {"sigma_m": 1e-3 if sigma_m is None else sigma_m, "sigma_rad": sigma_rad}
    elif sigma_m is not None:
        campaign["sigma_m"] = sigma_m
    if distance:
        ds = []
        for d in distance:
            try:
                a, b, v = d.rsplit(":", 2)
                ds.append({"a": a, "b": b, "distance": float(v)})
            except ValueError:
                raise RobocalError(f"--distance {d!r}: expected A:B:METRES") from None
        campaign["distances"] = ds
    for w in extras.get("import_warnings", []):
        err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = write_urdf_recording(out, desc, measure, campaign, table, tips=[t for t, _ in tips] if tips else None)
    err.print(f"imported {n} {measure} measurements of {len(desc.joint_names)} joints "
              f"({desc.root} → {', '.join(t for t, _ in tips) if tips else desc.tip}) into {out}",
              highlight=False, soft_wrap=True)


def _tips(items: list[str], measure: str, target: list[str]) -> list[tuple[str, tuple[str, ...]]] | None:
    """None for one chain (`--tip LINK`); [(link, (x, y, z) columns), …] for `--tip LINK=X,Y,Z` repeated."""
    from pipeline.errors import RobocalError

    if len(items) == 1 and "=" not in items[0]:
        return None
    out = []
    for it in items:
        link, sep, cols = it.partition("=")
        c = tuple(v.strip() for v in cols.split(","))
        if not sep or not link.strip() or len(c) != 3 or not all(c):
            raise RobocalError(f"--tip {it!r}: with several tips, each is LINK=X,Y,Z (its position columns)")
        out.append((link.strip(), c))
    if measure != "point":
        raise RobocalError(f"--tip LINK=X,Y,Z: several measured links need --measure point (got {measure})")
    if target:
        raise RobocalError("--target-cols and --tip LINK=X,Y,Z cannot be combined: give each link's columns with --tip")
    if len({t for t, _ in out}) != len(out):
        raise RobocalError("--tip: a link is given twice")
    return out


def _column_use(measure: str, tips, position: str, target: list[str], orientation: str, orientation_kind: str,
                plane: list[str], joints: list[str]) -> None:
    """One column, one quantity (`importers.column_use`): the options' columns as the user typed them."""
    from pipeline.importers.column_use import check_column_use

    groups: list = []
    if tips:
        groups += [(f"--tip {link}={','.join(c)}", "position", c) for link, c in tips]
    elif measure in ("point", "pose"):
        groups += [(f"--position-cols {position!r}", "position", _cols(position))]
        groups += [(f"--target-cols {t!r}", "position", _cols(t)) for t in target]
    if measure == "pose":
        groups.append((f"--orientation-cols {orientation!r}", orientation_kind, _cols(orientation)))
    if measure == "plane":
        groups += [(f"--plane {p!r}", "offset", (pl["offset"],)) for p in plane
                   for _, pl in [parse_plane(p)] if isinstance(pl["offset"], str)]
    check_column_use(groups, joints)


def _coupled_names(coupled: list[str]) -> list[str]:
    from pipeline.models.coupling import parse_coupling

    return [parse_coupling(c)[0] for c in coupled]


def _tree_desc(urdf: Path, root: str, tips: list, coupled: list[str]):
    """A description whose movable joints are the tree's read joints (`importers.tree_description`)."""
    from pipeline.importers.tree_description import tree_description

    return tree_description(urdf, root, [t for t, _ in tips], coupled)[0]
