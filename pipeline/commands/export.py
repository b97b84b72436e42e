"""``loomlight export fibers.zarr -o fibers.txt|fibers.bcc``: realized fibres for other renderers."""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("export")
    def export(
        fibers: Path = typer.Argument(..., help="A fibers artifact (loomlight realize)."),
        out: Path = typer.Option(..., "-o", "--out", help=".txt: Mitsuba 3 curve text ('x y z r' per line, blank "
                                                        "line between curves); .bcc: polyline Binary Curve Collection."),
    ):
        """Write realized fibres as Mitsuba 3 curve text or a polyline BCC file."""
        import numpy as np

        from ..artifacts import Artifact
        from ..curveset import CurveSet
        from ..errors import LoomError
        from ..io import bcc

        art = Artifact(fibers, kind="fibers")
        pts = np.asarray(art["points"], np.float32)
        rad = np.asarray(art["point_radius"], np.float32)
        off = np.asarray(art["fiber_offsets"], np.int64)
        suffix = out.suffix.lower()
        if suffix not in (".txt", ".bcc"):
            raise LoomError(out, None, "the output must end in .txt (Mitsuba curves) or .bcc")
        out.parent.mkdir(parents=True, exist_ok=True)
        if suffix == ".txt":
            tmp = out.with_name(f".{out.name}.tmp")
            write_mitsuba_txt(tmp, pts, rad, off)
            tmp.replace(out)
        else:
            curves = [pts[off[f]:off[f + 1]] for f in range(len(off) - 1)]
            cs = CurveSet(points=curves, closed=[False] * len(curves), group=["other"] * len(curves),
                          curve_type="polyline", source_format="bcc")
            bcc.write(out, cs, curve_type="polyline", text="loomlight realized fibres")
        typer.echo(f"wrote {out} ({len(off) - 1} curves)")


def write_mitsuba_txt(path, pts, rad, off):
    """Mitsuba 3 curve text: one 'x y z r' line per control point, a blank line between curves."""
    import numpy as np

    rows = np.concatenate([pts.astype(np.float64), rad.astype(np.float64)[:, None]], axis=1)
    lines = [" ".join(f"{v:.9g}" for v in row) for row in rows.tolist()]
    ends = set((off[1:] - 1).tolist())
    with open(path, "w") as f:
        for i, line in enumerate(lines):
            f.write(line)
            f.write("\n")
            if i in ends and i != len(lines) - 1:
                f.write("\n")
