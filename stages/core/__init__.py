"""The ground floor: kernels more than one stage needs (splines, frames, projection,
acceleration structures, random numbers, BCSDF, SH/SG, shell traversal)."""
