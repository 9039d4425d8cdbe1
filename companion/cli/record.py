"""`wireavoid log info FILE` and `wireavoid replay FILE`: flight recordings and their replay."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

log_app = typer.Typer(
    help="Flight recordings (MCAP): `sim --record`, `run --record`.", rich_markup_mode=None
)

FileArgument = Annotated[
    Path, typer.Argument(help="a recording (.mcap; its parts FILE-001.mcap ... follow it)")
]


@log_app.command("info")
def info(
    file: FileArgument,
    json_output: Annotated[bool, typer.Option("--json", help="one JSON object on stdout")] = False,
) -> None:
    """Summarise a recording: parts, size, time span, channels (messages, rate), frame sizes,
    the mission's events and the last stage timings."""
    from companion.record.reader import RecordingError, summary

    try:
        s = summary(file)
    except (RecordingError, FileNotFoundError) as e:
        raise typer.BadParameter(str(e)) from e
    if json_output:
        typer.echo(json.dumps(s))
        return
    typer.echo(f"{s['file']}: {len(s['parts'])} part(s), {s['size_bytes'] / 1e6:.2f} MB")
    typer.echo(
        f"time {s['start_s']} .. {s['end_s']} s ({s['duration_s']} s), {s['messages']} messages, "
        f"{s['frames']} frames (colour {s['image_shape']}, disparity {s['disparity_shape']})"
    )
    for name, c in sorted(s["channels"].items()):
        typer.echo(f"  {name:<28} {c['schema']:<26} {c['messages']:>7} msgs  {c['rate_hz']} Hz")
    for event in s["events"]:
        typer.echo(f"  {event['t_s']:9.2f} s  {event['state']:<9} {event['text']}")
    typer.echo(f"mission: {s['mission_state']}")


def replay(
    file: FileArgument,
    json_output: Annotated[bool, typer.Option("--json", help="one JSON object on stdout")] = False,
    view: Annotated[
        bool, typer.Option("--view", help="show the replay live in Foxglove (wireavoid[view])")
    ] = False,
    view_port: Annotated[int, typer.Option("--view-port", help="live view port")] = 8765,
    bless: Annotated[
        bool,
        typer.Option(
            "--bless",
            help="write the replayed outputs into the recording (after an intentional change: "
            "the regression data's new reference)",
        ),
    ] = False,
    probe: Annotated[
        list[str] | None,
        typer.Option(
            "--probe",
            help="N,E,D (local NED, m): report when the replayed map first held this point, "
            "and each planning cycle at which its answer changed (repeat for more points)",
        ),
    ] = None,
) -> None:
    """Re-run perception, mapping and planning on a recording's inputs and report where their
    outputs differ from the recorded ones (first divergence, counts, largest difference per
    topic). Exit status 0 when nothing diverged (or after --bless)."""
    from companion.record.reader import RecordingError, recording_parts
    from companion.record.replay import bless as bless_recording
    from companion.record.replay import recording_settings
    from companion.record.replay import replay as run_replay

    try:
        parts = recording_parts(file)
        settings = recording_settings(parts[0])
    except (RecordingError, FileNotFoundError) as e:
        raise typer.BadParameter(str(e)) from e
    if bless and len(parts) > 1:
        raise typer.BadParameter("--bless rewrites one-part recordings only")
    probes = _probe_points(probe or [])
    live = None
    if view:
        from companion.view.live import LiveView

        live = LiveView.start(settings, view_port)
    try:
        result, replayer = run_replay(
            parts,
            settings,
            on_replayed=None if live is None else live.on_replayed,
            probes_ned_m=probes,
        )
    finally:
        if live is not None:
            live.close()
    out = result.to_dict()
    if bless:
        out["blessed"] = str(bless_recording(parts[0], replayer))
    if json_output:
        typer.echo(json.dumps(out))
    else:
        typer.echo(
            f"{out['messages']} messages, {out['messages_replayed']} replayed, "
            f"{out['divergences']} divergent"
        )
        for name, topic in out["topics"].items():
            largest = ", ".join(f"{k} {v}" for k, v in topic["largest_difference"].items())
            typer.echo(
                f"  {name:<10} {topic['replayed']:>6} replayed {topic['divergent']:>5} "
                f"divergent; largest: {largest or '-'}"
            )
        if out["first_divergence"]:
            typer.echo(f"first divergence: {json.dumps(out['first_divergence'])}")
        if bless:
            typer.echo(f"blessed: {out['blessed']}")
        for p in out.get("probes", []):
            typer.echo(f"probe {p['point_ned_m']}:")
            for c in p["changes"]:
                typer.echo(
                    f"  {c['t_s']:9.2f} s  collision {c['collision']!s:<5} solid "
                    f"{c['solid']!s:<5} seen {c['seen']!s:<5} occupancy {c['occupancy']}"
                )
    raise typer.Exit(0 if bless or out["divergences"] == 0 else 1)


def _probe_points(texts: list[str]) -> np.ndarray | None:
    """`(P, 3)` NED points from `--probe N,E,D` texts (None without any)."""
    if not texts:
        return None
    points = []
    for text in texts:
        try:
            point = [float(v) for v in text.split(",")]
        except ValueError:
            point = []
        if len(point) != 3 or not all(math.isfinite(v) for v in point):
            raise typer.BadParameter(f"--probe {text!r}: expected N,E,D in metres, e.g. 9,0,-2")
        points.append(point)
    return np.array(points)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid log info` and `wireavoid replay`."""
    app.add_typer(log_app, name="log")
    app.command("replay")(replay)
