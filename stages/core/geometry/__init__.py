"""Ray geometry of explicit fibres: ``capsule`` (ray-capsule intersection, normal, point-segment
distance), ``slab`` (ray-box slab test), ``frames`` (orthonormal bases), ``bvh`` (the SAH BVH over
capsule chains) and ``surface`` (the surface-scene interface integrators query, per scene class)."""
