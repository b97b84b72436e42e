"""The renderer, one concept per module: camera, lights, media, BCSDFs, integrators."""
