"""`wireavoid plan-library` and `wireavoid bench planning --json`."""

import json
import math
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.planning import load_library
from planning.params import PlanningParams


def test_plan_library_writes_the_library_and_its_plot(tmp_path: Path) -> None:
    out, plot = tmp_path / "x.npz", tmp_path / "x.png"
    result = CliRunner().invoke(app, ["plan-library", "--out", str(out), "--plot", str(plot)])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["library_size"] == PlanningParams().library_size == len(summary["labels"])
    assert summary["waypoints"] == 20 and summary["horizon_s"] == 4.0
    assert plot.read_bytes()[:4] == b"\x89PNG"
    library = load_library(out)
    assert library.size == summary["library_size"]
    np.testing.assert_allclose(library.initial_speeds_mps, summary["speed_bins_mps"], atol=1e-3)

    again = CliRunner().invoke(app, ["plan-library", "--load", str(out)])
    assert again.exit_code == 0, again.output
    assert json.loads(again.output)["labels"] == summary["labels"]


def test_a_config_file_changes_the_library(tmp_path: Path) -> None:
    config = tmp_path / "small.toml"
    config.write_text("[planning]\nturn_levels = 1\nclimb_levels = 0\nspeed_levels = 1\n")
    result = CliRunner().invoke(app, ["plan-library", "--config", str(config)])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["labels"] == ["left-1", "straight", "right-1", "stop"]


def test_bench_planning_reports_cycle_ms_and_rows() -> None:
    args = ["bench", "planning", "--json", "--repeats", "3", "--shapes", "1,1,1", "--nodes", "1,5"]
    result = CliRunner().invoke(app, [*args, "--map", "synthetic"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert isinstance(report["cycle_ms"], float) and math.isfinite(report["cycle_ms"])
    assert report["cycle_nodes"] == 20
    assert report["cycle_library_size"] == PlanningParams().library_size
    rows = report["rows"]
    assert [(r["library_size"], r["nodes"]) for r in rows] == [(10, 1), (10, 5)]
    for row in rows:
        assert row["all_waypoints"] == 10 * 20
        assert math.isfinite(row["select_all_ms"]) and math.isfinite(row["select_chunked_ms"])
