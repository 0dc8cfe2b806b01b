"""The ``decco-warp`` command line: a thin layer over the Python API."""

from __future__ import annotations

from typing import Optional

import typer

from ._version import __version__

app = typer.Typer(
    name="decco-warp",
    help="Soft-sphere DEM collisions of self-gravitating rubble piles on NVIDIA Warp.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

DeviceOption = typer.Option(
    None, "--device", help="cpu, cuda or cuda:N (default: $DECCO_DEVICE, else CUDA if present, else cpu)."
)


def fail(message: str, code: int = 2) -> None:
    """Print a one-line error and exit: bad input is exit code 2, never a traceback."""
    typer.echo(f"decco-warp: error: {message}", err=True)
    raise typer.Exit(code)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"decco-warp {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Soft-sphere DEM collisions of self-gravitating rubble piles on NVIDIA Warp."""


@app.command()
def info(device: Optional[str] = DeviceOption) -> None:
    """Show the Warp version, the devices found and the one a run would use."""
    import warp as wp

    from .device import DeviceError, describe_devices, resolve_device
    from .engine import choose_layout

    try:
        chosen = resolve_device(device)
    except DeviceError as error:
        fail(str(error))
    typer.echo(f"decco-warp {__version__}")
    typer.echo(f"warp-lang  {wp.config.version}")
    typer.echo("devices:")
    for entry in describe_devices():
        marker = "*" if entry["name"] == chosen else " "
        typer.echo(f"  {marker} {entry['name']:<8} {entry['description']}")
    layout = choose_layout(10_240, chosen)
    typer.echo(f"would use: {chosen}")
    typer.echo(
        f"force kernel layout at N = 10 240: tile {layout.tile}, {layout.particles_per_block} particle(s) "
        f"per block, {layout.block_dim} thread(s) per block"
    )
