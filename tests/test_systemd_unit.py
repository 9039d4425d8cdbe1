"""The systemd unit: `systemd-analyze verify` passes without a word, and it is hardened."""

from __future__ import annotations

import configparser
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
UNIT = REPO / "systemd" / "wireavoid.service"
WIREAVOID = Path(sys.executable).parent / "wireavoid"  # installed with the venv


def installed_unit(folder: Path, text: str | None = None) -> Path:
    """The unit with ExecStart pointed at this checkout's `wireavoid` (verify checks it exists)."""
    text = UNIT.read_text() if text is None else text
    unit = folder / "wireavoid.service"
    unit.write_text(re.sub(r"(?m)^ExecStart=\S+", f"ExecStart={WIREAVOID}", text))
    return unit


def verify(unit: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["systemd-analyze", "verify", "--man=no", str(unit)], capture_output=True, text=True
    )


def service_section() -> dict[str, list[str]]:
    """Every key of [Service] with all its values (DeviceAllow= repeats)."""
    values: dict[str, list[str]] = {}
    section = None
    for line in UNIT.read_text().splitlines():
        if line.startswith("["):
            section = line.strip("[]")
        elif section == "Service" and "=" in line and not line.startswith("#"):
            key, value = line.split("=", 1)
            values.setdefault(key, []).append(value)
    return values


def test_the_unit_passes_systemd_analyze_verify(tmp_path: Path) -> None:
    assert WIREAVOID.exists()
    result = verify(installed_unit(tmp_path))
    assert result.returncode == 0 and result.stderr == "" and result.stdout == "", result.stderr


def test_verify_would_catch_a_broken_unit(tmp_path: Path) -> None:
    broken = UNIT.read_text().replace("ProtectSystem=strict", "ProtectSytem=strict")
    result = verify(installed_unit(tmp_path, broken.replace("Type=notify", "Type=bogus")))
    assert "Unknown key 'ProtectSytem'" in result.stderr
    assert "Failed to parse service type" in result.stderr


def test_the_unit_is_hardened(tmp_path: Path) -> None:
    service = service_section()
    expected = {
        "User": "wireavoid",
        "Group": "wireavoid",
        "ProtectSystem": "strict",
        "NoNewPrivileges": "yes",
        "PrivateTmp": "yes",
        "ProtectHome": "yes",
        "DevicePolicy": "closed",
        "CapabilityBoundingSet": "",
    }
    for key, value in expected.items():
        assert service.get(key) == [value], key
    # devices: the cameras, the autopilot's serial port and the GPU, nothing else
    allowed = {
        "char-usb_device rw",
        "char-video4linux rw",
        "char-ttyTHS rw",
        "char-ttyACM rw",
        "char-ttyUSB rw",
        "/dev/nvmap rw",
        "char-nvhost* rw",
        "char-nvgpu* rw",
        "char-nvidia* rw",
    }
    assert set(service["DeviceAllow"]) == allowed
    report = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", str(installed_unit(tmp_path))],
        capture_output=True,
        text=True,
    )
    exposure = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", report.stdout)
    assert exposure is not None, report.stdout + report.stderr
    assert float(exposure.group(1)) <= 3.1  # "OK"; 3.5 before DevicePolicy and friends


def test_the_unit_parses_as_ini() -> None:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.read_string(UNIT.read_text())
    assert parser["Unit"]["After"].split() == ["network-online.target", "mosquitto.service"]
    assert parser["Install"]["WantedBy"] == "multi-user.target"
