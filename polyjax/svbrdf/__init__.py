"""Spatially varying BRDFs: simulate a capture of a flat sample, fit every texel in closed form, write the
coefficient textures shard by shard, re-render under a new light; across devices and processes.

``python -m polyjax svbrdf --help`` runs the pipeline from the command line (``docs/scale.md``).
"""

from ._capture import (
    Capture,
    blend_map,
    blended_brdf,
    directions,
    hemisphere_lights,
    photograph,
    radiance,
    relight,
    simulate_capture,
    spread_cameras,
    texel_positions,
)
from ._distributed import ROWS, fit_rows_distributed, free_port, initialize, local_rows, row_mesh
from ._fit import fit_capture
from ._shards import MANIFEST, read_texture_shards, write_texture_shards

__all__ = [
    "Capture", "MANIFEST", "ROWS", "blend_map", "blended_brdf", "directions", "fit_capture", "fit_rows_distributed",
    "free_port", "hemisphere_lights", "initialize", "local_rows", "photograph", "radiance", "read_texture_shards",
    "relight", "row_mesh", "simulate_capture", "spread_cameras",
    "texel_positions", "write_texture_shards",
]
