"""The ``quad-sindy`` command line: thin wrappers that parse arguments and call the library."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__)
bench_app = typer.Typer(no_args_is_help=True, help="Speed benchmarks (numbers and ratios).")
app.add_typer(bench_app, name="bench")


class SystemName(str, Enum):
    """Vehicle models."""

    planar = "planar"
    quad6dof = "quad6dof"


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


@app.command()
def simulate(
    out: Annotated[Path, typer.Option(help="CSV file to write")],
    case: Annotated[str, typer.Option(help="A, B, C or a trajectory name")] = "C",
    system: Annotated[SystemName, typer.Option(help="vehicle model")] = SystemName.planar,
    dt: Annotated[float, typer.Option(help="control and sample period [s]")] = 0.01,
    duration: Annotated[float, typer.Option(help="final time [s]")] = 10.0,
) -> None:
    """Flies a reference under the PD controller and writes t, states, inputs, references."""
    from quad_envs.io import write_csv
    from quad_envs.simulate import simulate_case

    try:
        run = simulate_case(case, system.value, dt=dt, duration=duration)
    except ValueError as exc:
        _fail(str(exc))
    header, rows = run.table()
    write_csv(out, header, rows)
    typer.echo(f"wrote {len(rows)} rows to {out}")


@bench_app.command("envs")
def bench_envs_cmd(
    num_envs: Annotated[int, typer.Option(help="vector env size")] = 1024,
    seconds: Annotated[float, typer.Option(help="minimum timing per measurement [s]")] = 2.0,
) -> None:
    """Steps/s of PlanarQuad-v0 and Quad6DOF-v0 (single and vector) against Pendulum-v1."""
    import quad_envs
    from quad_envs.bench import bench_envs

    rows = bench_envs(quad_envs.ENV_IDS, num_envs, seconds)
    typer.echo(f"{'env':<16} {'mode':<14} {'steps/s':>12} {'x Pendulum-v1':>14}")
    for row in rows:
        typer.echo(
            f"{row['env']:<16} {row['mode']:<14} {row['steps_per_s']:>12,.0f} {row['ratio']:>14.2f}"
        )


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="output folder")] = Path("out/demo"),
) -> None:
    """Simulates the paper's cases A, B, C: CSVs and response plots."""
    from quad_envs.io import write_csv
    from quad_envs.plotting import plot_response
    from quad_envs.simulate import simulate_case

    for case in "ABC":
        run = simulate_case(case)
        header, rows = run.table()
        write_csv(out / f"case_{case}.csv", header, rows)
        plot_response(run, out / f"case_{case}.png", title=f"Paper case {case}")
    typer.echo(f"wrote CSVs and response plots of cases A, B, C to {out}/")


def main() -> None:
    """Console entry point."""
    app()
