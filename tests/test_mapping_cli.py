"""`wireavoid calibrate-sigma` on a folder of samples, and `wireavoid map-sim`."""

import json
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.mapping import _simulated_board_shots
from geometry.camera import stereo_rig_from_params
from mapping.droan.params import MappingParams


def test_calibrate_sigma_reads_a_sample_folder(tmp_path: Path) -> None:
    rig = stereo_rig_from_params(MappingParams().camera)
    for i, (left, disparity) in enumerate(_simulated_board_shots(rig, (8, 5), 0.1, 0.35)):
        cv2.imwrite(str(tmp_path / f"shot{i:02d}_left.png"), left)
        np.save(tmp_path / f"shot{i:02d}_disp.npy", disparity)
    result = CliRunner().invoke(app, ["calibrate-sigma", str(tmp_path), "--json"])
    assert result.exit_code == 0, result.output
    fit = json.loads(result.output)
    assert fit["images_used"] == fit["images"] == 20
    assert abs(fit["sigma_px"] - 0.35) < 0.04


def test_map_sim_writes_a_ply_of_occupied_voxels(tmp_path: Path) -> None:
    out = tmp_path / "map.ply"
    result = CliRunner().invoke(app, ["map-sim", "--out", str(out), "--frames", "3"])
    assert result.exit_code == 0, result.output
    header = out.read_bytes().split(b"end_header")[0].decode()
    count = int(header.split("element vertex ")[1].split()[0])
    assert count > 1000
