"""`wireavoid bench mapping` on a short sequence: JSON contract and agreement with OctoMap."""

from companion.cli.bench_mapping import run_mapping_benchmark
from mapping.droan.params import MappingParams

KEYS = {
    "droan_update_ms",
    "octomap_insert_ms",
    "speedup_vs_octomap",
    "library_check_ms",
    "missed_by_droan",
    "missed_by_octomap",
}


def test_bench_reports_the_issue_keys_and_droan_misses_nothing_octomap_catches() -> None:
    result = run_mapping_benchmark(MappingParams(), frame_count=4)
    assert result.keys() >= KEYS
    assert result["missed_by_droan"] == 0
    wires = result["details"]["agreement"]["wires"]
    assert wires["samples"] > 100
    assert wires["caught_by_droan"] > 0.9 * wires["samples"]  # stereo alone misses wires
    assert wires["caught_by_octomap"] < 0.5 * wires["samples"]
    assert result["details"]["droan_nodes"] == 4
