"""``loomlight lookup tables.zarr --points pts.npy -o res.npz``: seed 000 Algorithm 1 at given points."""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("lookup")
    def lookup(
        tables: Path = typer.Argument(..., help="A tables artifact (loomlight tables)."),
        points: Path = typer.Option(..., "--points", help="(N, 3) float array of fabric-space points (.npy)."),
        out: Path = typer.Option(..., "-o", "--out", help="Output .npz: inside, yarn, kind, direction, density, albedo."),
    ):
        """Inside a fibre or not, yarn index (-1 outside), kind (0 none, 1 regular, 2 loop, 3 hair), unit fibre
        direction (zero outside), density and albedo, for every point."""
        import numpy as np

        from ..errors import LoomError
        from ..procedural_runner import load_tables
        from stages.core.yarn.lookup import lookup_points

        if not points.exists():
            raise LoomError(points, None, "file not found")
        try:
            pts = np.load(points, allow_pickle=False)
        except (ValueError, OSError) as e:
            raise LoomError(points, None, f"not a .npy array: {e}") from None
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.dtype.kind not in "fiu":
            raise LoomError(points, None, f"expected an (N, 3) numeric array, got {pts.dtype} {pts.shape}")
        if not np.isfinite(pts).all():
            raise LoomError(points, f"row {int(np.argmax(~np.isfinite(pts).all(axis=1)))}", "non-finite coordinate")
        cv, tab, _ = load_tables(tables)
        inside, yarn, kind, direction, density, albedo = lookup_points(cv, tab, np.ascontiguousarray(pts, np.float64))
        if out.suffix != ".npz":
            raise LoomError(out, None, "the output file must end in .npz")
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp.npz")
        np.savez(tmp, inside=inside, yarn=yarn.astype(np.int64), kind=kind.astype(np.int64), direction=direction,
                 density=density, albedo=albedo)
        tmp.replace(out)
        typer.echo(f"wrote {out} ({int(inside.sum())} of {len(pts)} points inside a fibre)")
