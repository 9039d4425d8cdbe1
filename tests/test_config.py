"""The one typed configuration: TOML + environment, validation, generated docs."""

from pathlib import Path

import pytest
from pydantic import ValidationError

from companion.cli.config_docs import configuration_markdown, settings_toml
from companion.cli.settings import load_sim_settings
from companion.config import load_settings

REPO = Path(__file__).resolve().parents[1]


def test_defaults_carry_the_thesis_values() -> None:
    settings = load_settings()
    assert settings.mapping.disparity_sigma_px == pytest.approx(0.23)
    assert settings.mapping.wire_depth_near_m == 4.0
    assert settings.mapping.wire_depth_far_m == 20.0
    assert settings.mapping.keyframe_translation_m == 0.5
    assert settings.mapping.keyframe_rotation_deg == 18.0
    assert settings.perception.confidence_threshold == pytest.approx(0.95)


def test_toml_file_then_environment_override(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "wireavoid.toml"
    path.write_text("[mapping]\nrobot_radius_m = 0.7\ndisparity_sigma_px = 0.3\n")
    monkeypatch.setenv("WIREAVOID_MAPPING__ROBOT_RADIUS_M", "0.4")
    settings = load_settings(path)
    assert settings.mapping.robot_radius_m == pytest.approx(0.4)  # env beats file
    assert settings.mapping.disparity_sigma_px == pytest.approx(0.3)  # file beats default


def test_unknown_key_and_out_of_bounds_value_are_rejected(tmp_path: Path) -> None:
    typo = tmp_path / "typo.toml"
    typo.write_text("[mapping]\nrobot_radius = 0.7\n")
    with pytest.raises(ValidationError, match="robot_radius"):
        load_settings(typo)
    for section in ("link", "perception", "mapping", "catenary", "planning", "vehicle_sim"):
        misspelt = tmp_path / f"{section}.toml"
        misspelt.write_text(f"[{section}]\nno_such_field = 1\n")
        with pytest.raises(ValidationError, match="no_such_field"):
            load_sim_settings(misspelt)


def test_the_flight_process_rejects_the_simulator_sections(tmp_path: Path) -> None:
    path = tmp_path / "drone.toml"
    path.write_text("[vehicle_sim]\nmass_kg = 2.0\n")
    assert load_sim_settings(path).vehicle_sim.mass_kg == 2.0
    with pytest.raises(ValidationError, match="vehicle_sim"):
        load_settings(path)
    negative = tmp_path / "negative.toml"
    negative.write_text("[mapping]\nrobot_radius_m = -1\n")
    with pytest.raises(ValidationError, match="robot_radius_m"):
        load_settings(negative)


def test_generated_toml_reads_back_to_the_same_settings(tmp_path: Path) -> None:
    settings = load_sim_settings()
    path = tmp_path / "roundtrip.toml"
    path.write_text(settings_toml(settings))
    assert load_sim_settings(path) == settings


def test_every_setting_is_documented_and_the_reference_is_current() -> None:
    for _, section in load_sim_settings():
        for name, info in type(section).model_fields.items():
            assert info.description, f"{type(section).__name__}.{name} has no description"
    committed = (REPO / "docs" / "configuration.md").read_text()
    assert committed.strip() == configuration_markdown().strip(), (
        "docs/configuration.md is stale: run `wireavoid config docs --out docs/configuration.md`"
    )
