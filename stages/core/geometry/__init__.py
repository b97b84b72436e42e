"""Ray geometry of explicit fibres: capsules (``capsule``) and the SAH BVH over capsule chains (``bvh``)."""
