"""`robocal acquire`, `robocal device-sim`, `robocal recover` (see docs/guide/acquire.md)."""

from __future__ import annotations

import json
import shlex
import sys
import tempfile
from pathlib import Path

import typer

from pipeline.cli import SIMULATE, app, err, force_option, simulate_app
from pipeline.errors import RobocalError

ROLES = ("bridge", "tracker", "scanner")


def _parse_devices(specs: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for s in specs:
        role, sep, port = s.partition("=")
        if not sep or not port:
            raise RobocalError(f"--device {s!r}: expected ROLE=PORT, e.g. bridge=/dev/ttyUSB0")
        if role not in ROLES:
            raise RobocalError(f"--device {s!r}: role must be one of {', '.join(ROLES)}")
        if role in out:
            raise RobocalError(f"--device {role} given twice")
        out[role] = port
    return out


@app.command("acquire", rich_help_panel=SIMULATE)
def acquire_cmd(
    device: list[str] = typer.Option(..., "--device", help="ROLE=PORT (bridge, tracker, scanner); repeatable."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    max_s: float = typer.Option(None, "--max-s", help="Stop after this many seconds."),
    connect_timeout: float = typer.Option(10.0, "--connect-timeout", help="Give up if a port never opens (s)."),
    fsync: bool = typer.Option(False, "--fsync", help="fsync at every chunk flush (survives power loss, not only a crash)."),
    summary: Path = typer.Option(None, "--summary", help="Also write the acquisition summary (JSON) here."),
    silence_s: float = typer.Option(1.5, "--silence-s", help="A device silent this long after sending is treated as gone (s)."),
    give_up_s: float = typer.Option(30.0, "--give-up-s", help="Stop when the bridge has been gone this long (s; 0: never)."),
) -> None:
    """Record calibration devices over serial ports until the bridge's campaign is complete or stopped."""
    from pipeline.acquire.run import acquire
    from pipeline.recording.output import check_output, distinct_outputs, generated

    devs = _parse_devices(device)
    check_output(out, force=None)  # a recording is never replaced by an acquisition (no --force here)
    if summary is not None:
        check_output(summary, "summary")  # before the acquisition starts: never over a file robocal did not create
        distinct_outputs(out=out, summary=summary)
    live = err.is_terminal

    with err.status("waiting for devices…") as st:
        def status(line: str) -> None:
            if live:
                st.update(line)

        def log(msg: str) -> None:
            err.print(f"[yellow]{msg}[/]", highlight=False, soft_wrap=True)

        last = {"t": 0.0}

        def status_plain(line: str) -> None:
            import time
            if time.monotonic() - last["t"] > 2.0 and line != last.get("line"):
                last["t"], last["line"] = time.monotonic(), line
                err.print(line, highlight=False, soft_wrap=True)

        s = acquire(devs, out, max_s=max_s, connect_timeout_s=connect_timeout, fsync=fsync,
                    status=status if live else status_plain, log=log, silence_s=silence_s, give_up_s=give_up_s)
    if summary is not None:
        summary.parent.mkdir(parents=True, exist_ok=True)
        summary.write_text(json.dumps(generated(s), indent=2) + "\n")
    for role, d in s["devices"].items():
        ev = ", ".join(f"{n} {t}" for t, n in d["events"].items()) or "no events"
        clk = d["clock"]
        clk_s = f"; clock offset {clk['offset_ns'] / 1e9:+.6f} s, drift {clk['drift_ppm']:+.2f} ppm" if clk else ""
        drive = f" with {', '.join(d['drive_state'])}" if d.get("drive_state") else ""
        err.print(f"{role}: {d['samples']} samples{drive}, {ev}; {d['frames']} frames, {d['missing_frames']} missing, "
                  f"{d['bad_frames']} bad, {d['garbage_bytes']} garbage bytes, {len(d['gaps'])} gaps{clk_s}",
                  highlight=False, soft_wrap=True)
    err.print(f"wrote {out} ({s['stop_reason']})", highlight=False)


@app.command("recover", rich_help_panel=SIMULATE)
def recover_cmd(
    src: Path = typer.Argument(..., help="A recording cut short (crash, SIGKILL, full disk)."),
    dst: Path = typer.Argument(..., help="Where to write the restored recording."),
    force: bool = force_option(),
) -> None:
    """Restore every complete record of a damaged recording into a well-formed MCAP file."""
    from pipeline.acquire.recover import recover

    s = recover(src, dst, force=force)
    state = "source was complete" if s["complete_source"] else f"source cut short ({s['damage'] or 'no footer'})"
    err.print(f"recovered {s['messages']} messages, {s['metadata']} metadata records on {s['channels']} channels "
              f"into {dst}; {state}", highlight=False, soft_wrap=True)


@app.command("device-sim", rich_help_panel=SIMULATE)
def device_sim_cmd(
    system: str = typer.Argument(..., help="Reference system, e.g. arc-welder (see `robocal simulate --help`)."),
    recording: Path = typer.Option(None, "--recording", help="Play this recording instead of simulating one."),
    seed: int = typer.Option(0, "--seed", help="Seed of the simulated campaign and of the impairments."),
    sim_args: str = typer.Option("", "--sim-args", help="Extra options for `robocal simulate SYSTEM`, e.g. '--contacts 30'."),
    campaign: list[Path] = typer.Option([], "--campaign", help="Play this planned campaign (robocal plan --out) as "
                                        "executed on the simulated true robot; repeat for stages."),
    speed: float = typer.Option(1.0, "--speed", min=0.01, help="Play this many times faster than real time."),
    batch: int = typer.Option(1, "--batch", min=1, max=1000, help="Encoder samples per SAMPLES frame."),
    corrupt: float = typer.Option(0.0, "--corrupt", min=0.0, max=1.0, help="Probability of flipping each byte."),
    drop: float = typer.Option(0.0, "--drop", min=0.0, max=1.0, help="Probability of dropping each byte."),
    noise: float = typer.Option(0.0, "--noise", min=0.0, max=1.0, help="Probability of a burst of line noise before a frame."),
    drift_ppm: float = typer.Option(0.0, "--drift-ppm", help="Device clock drift (ppm)."),
    offset_s: float = typer.Option(0.0, "--offset-s", help="Device clock offset (s)."),
    disconnect_every: float = typer.Option(0.0, "--disconnect-every", help="Unplug the device every this many wall seconds (0: never)."),
    disconnect_for: float = typer.Option(1.0, "--disconnect-for", help="Wall seconds each disconnect lasts."),
    disconnect_device: str = typer.Option("bridge", "--disconnect-device", help="Which device is unplugged."),
    link_dir: Path = typer.Option(None, "--link-dir", help="Folder for the stable per-device symlinks (default: a temp dir)."),
    report: Path = typer.Option(None, "--report", help="Write what was sent, damaged and lost (JSON) here."),
    wait: float = typer.Option(60.0, "--wait", help="Seconds to wait for the host to open the ports."),
) -> None:
    """Virtual devices: play a campaign of SYSTEM over pseudo-terminals (prints ROLE=PATH lines)."""
    from pipeline.acquire.devicesim import Clock, Impairments, device_streams, play
    from pipeline.recording.reader import read_recording
    from pipeline.recording.output import check_output, generated
    from pipeline.recording.schemas import META_CAMPAIGN

    if report is not None:
        check_output(report, "report")  # before anything is simulated or played
    tmp = tempfile.TemporaryDirectory(prefix="robocal-devsim-")
    if campaign and recording is not None:
        raise RobocalError("device-sim: give --campaign or --recording, not both")
    if recording is None:
        recording = Path(tmp.name) / "campaign.mcap"
        try:
            plan_args = [a for c in campaign for a in ("--campaign", str(c))]
            simulate_app([system, "--out", str(recording), "--seed", str(seed), *plan_args, *shlex.split(sim_args)],
                         standalone_mode=False)
        except SystemExit as e:
            if e.code:
                raise RobocalError(f"device-sim: `robocal simulate {system}` failed (exit {e.code})") from None
        except Exception as e:  # click usage errors: unknown system or option
            raise RobocalError(f"device-sim: cannot simulate {system!r}: {e}") from None
    rec = read_recording(recording)
    rec_system = rec.metadata.get(META_CAMPAIGN, {}).get("system")
    if rec_system and rec_system != system:
        raise RobocalError(f"{recording}: is a {rec_system} campaign, not {system}")
    t0 = min(m["timestamp_ns"] for msgs in rec.messages.values() for m in msgs[:1] if "timestamp_ns" in m)  # not /tf
    clock = Clock(t0=int(t0), offset_ns=int(round(offset_s * 1e9)), drift=drift_ppm * 1e-6)
    streams = device_streams(rec, clock, batch=batch)
    imp = Impairments(corrupt, drop, noise, disconnect_every, disconnect_for, disconnect_device, seed)

    def announce(line: str) -> None:
        print(line, flush=True)

    rep = play(streams, link_dir or Path(tmp.name) / "dev", speed=speed, imp=imp, wait_s=wait, announce=announce)
    doc = {"wall_start_ns": rep.wall_start_ns, "sim_start_ns": rep.sim_start_ns, "speed": speed,
           "clock": {"t0": clock.t0, "offset_ns": clock.offset_ns, "drift": clock.drift}, "devices": rep.devices}
    if report is not None:
        report.parent.mkdir(parents=True, exist_ok=True)
        report.write_text(json.dumps(generated(doc)) + "\n")
    for role, d in rep.devices.items():
        err.print(f"{role}: sent {d['sent']} of {d['frames']} frames, {len(d['damaged_seqs'])} damaged, "
                  f"{len(d['lost_seqs'])} lost in {len(d['disconnects'])} disconnects", highlight=False)
    tmp.cleanup()
    sys.stdout.flush()
