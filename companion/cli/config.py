"""`wireavoid config`: show the effective settings and generate their reference."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

config_app = typer.Typer(
    help="Show the effective configuration or its reference.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@config_app.command("show")
def show(
    config: Annotated[
        Path | None,
        typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
    ] = None,
) -> None:
    """Print the effective settings (file + WIREAVOID_* overrides) as TOML."""
    from companion.cli.config_docs import settings_toml
    from companion.cli.settings import load_sim_settings

    typer.echo(settings_toml(load_sim_settings(config)))


@config_app.command("docs")
def docs(
    out: Annotated[Path | None, typer.Option("--out", help="write here instead of stdout")] = None,
) -> None:
    """Print (or write) the Markdown reference of every setting, from the code's defaults."""
    from companion.cli.config_docs import configuration_markdown

    text = configuration_markdown()
    if out is None:
        typer.echo(text)
    else:
        out.write_text(text + "\n")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid config show|docs`."""
    app.add_typer(config_app, name="config")
