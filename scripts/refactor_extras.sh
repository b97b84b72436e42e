#!/usr/bin/env bash
# Extra outputs beyond `make demo` for scripts/output_hashes.py: every source, material and format
# path the demo does not take. Usage: scripts/refactor_extras.sh DEMO_OUT (after make demo OUT=DEMO_OUT)
set -euo pipefail
O=$1
LL=.venv/bin/loomlight
X=$O/extras
mkdir -p $X
S=data/scenes/demo.toml
$LL ingest data/curves/ring_and_helix.bcc -o $X/ring.zarr --write $X/ring.obj
$LL ingest data/curves/two_polylines.obj -o $X/two.zarr --radius 0.01
$LL ingest data/curves/mitsuba_curves.txt -o $X/mts.zarr
$LL ingest data/drafts/twill_2x2.wif -o $X/twill.zarr
$LL ingest data/scenes/gentle_swatch.toml -o $X/gentle_yarns.zarr
$LL tables $X/gentle_yarns.zarr -o $X/gentle_tables.zarr --hair-mode free
# the gentle swatch has no camera nor light: the same fabric seen from above under a white sky
{ cat data/scenes/gentle_swatch.toml; printf '\n[camera]\norigin = [0.0, -0.9, 1.2]\ntarget = [0.0, 0.0, 0.0]\n\n[[lights]]\ntype = "constant"\nradiance = 1.0\n'; } > $X/gentle_camera.toml
$LL voxelize $O/tables.zarr -o $X/grid.zarr --res 24 24 6 --export-npy $X/npy
$LL render $S --method volpath --source grid --grid $X/grid.zarr --width 24 --height 18 --spp 2 -o $X/vol_grid.exr
$LL render $X/gentle_camera.toml --method volpath --source procedural --tables $X/gentle_tables.zarr --width 16 --height 12 --spp 1 -o $X/vol_free.exr
$LL render $S --method fiberpath --fibers $O/fibers.zarr --material lambert --width 24 --height 18 --spp 2 -o $X/fib_lambert.exr
$LL render data/scenes/draped_damask.toml --method fiberpath --fibers $O/damask_tiling.zarr --material lambert --width 24 --height 18 --spp 2 -o $X/damask_lambert.exr
$LL export $O/fibers.zarr -o $X/fibers.txt
(cd $X && sha256sum fibers.txt ring.obj > text_hashes.txt)
rm $X/fibers.txt
.venv/bin/python -c "
import numpy as np
rng = np.random.default_rng(0)
np.save('$X/pts.npy', rng.uniform([-0.4, -0.4, -0.05], [0.4, 0.4, 0.05], (20000, 3)))"
$LL lookup $O/tables.zarr --points $X/pts.npy -o $X/lookup.npz
