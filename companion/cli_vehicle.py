"""`wireavoid` commands of the vehicle domain."""

from __future__ import annotations

import typer


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""
