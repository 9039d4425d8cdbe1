"""`wireavoid bench catenary --json`: the report of the 3.4.1 simulation experiments."""

import json

from typer.testing import CliRunner

from companion.cli import app


def test_bench_catenary_reports_the_issue_keys() -> None:
    result = CliRunner().invoke(app, ["bench", "catenary", "--trials", "1", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    # one trial per scenario cell: every non-degenerate cell converges (measured 12/12)
    assert report["success_rate"] >= 11 / 12
    assert report["vertex_error_m_median"] < 1.0
    cells = {(c["placement"], c["wire"], c["cameras"]) for c in report["scenarios"]}
    assert len(cells) == 12 and ("avoidance", "near_straight", 16) in cells
    degenerate = report["degenerate_two_camera_case"]
    assert degenerate["ill_conditioned"] and not degenerate["confident"]
    assert degenerate["curve_error_m"] > 1.0  # wrong, and reported as such
