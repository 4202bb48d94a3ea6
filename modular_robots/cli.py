"""The ``modular-robots`` command: a thin shell over the Python API."""

from __future__ import annotations

import functools
from pathlib import Path

import click

from .composition import Composition, count_compositions, enumerate_compositions
from .exceptions import ModularRobotsError
from .scenario import load_scenario_or_catalog
from .urdf import write_urdf

__all__ = ["main"]


def _user_errors(command):
    """Show package errors as a one-line ``Error: …`` and exit 1, without a traceback."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except ModularRobotsError as exc:
            raise click.ClickException(str(exc)) from None

    return wrapper


_existing_file = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="modular-robots")
def main() -> None:
    """Find the best assembly of catalogue modules for a task, and how it moves."""


@main.command("enumerate")
@click.argument("source", type=_existing_file, metavar="SCENARIO_OR_CATALOG")
@click.option("--count", is_flag=True, help="Print the number of compositions per DOF instead of their names.")
@click.option("--dof", type=int, default=None, help="Only compositions with this many DOF.")
@_user_errors
def enumerate_command(source: Path, count: bool, dof: int | None) -> None:
    """Step A: list every composition the catalogue's grammar allows, one per line."""
    _, catalog = load_scenario_or_catalog(source)
    if count:
        counts = count_compositions(catalog, dof)
        click.echo("dof  compositions")
        for k, n in counts.items():
            click.echo(f"{k:<4d} {n}")
        click.echo(f"all  {sum(counts.values())}")
        return
    for composition in enumerate_compositions(catalog, dof):
        click.echo(composition.name)


@main.command("urdf")
@click.argument("composition")
@click.option("--scenario", "source", type=_existing_file, required=True,
              help="Scenario (payload from its task) or catalogue file.")
@click.option("--payload", type=click.FloatRange(min=0.0), default=None,
              help="Payload [kg]; default: the scenario's, or 0 for a catalogue.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="URDF file to write.")
@_user_errors
def urdf_command(composition: str, source: Path, payload: float | None, output: Path) -> None:
    """Write the URDF of COMPOSITION (e.g. B-J1-L2-E1), payload at tool0."""
    scenario, catalog = load_scenario_or_catalog(source)
    if payload is None:
        payload = scenario.task.payload if scenario else 0.0
    chain = Composition.from_name(composition, catalog)
    write_urdf(output, chain, catalog, payload)
    click.echo(f"wrote {output} ({chain.dof} joints, payload {payload:g} kg)")
