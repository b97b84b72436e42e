"""Scattering models, each with eval / pdf / sample: the fibre BCSDF (``bcsdf``), a Lambertian
surface (``lambert``), the SGGX micro-flake phase function (``sggx``), the yarn-level BYSDF of seed 004
(``bysdf``: reflection side at the entry point, transmission side to the exit point); ``material`` packs a model and
its parameters into one row and dispatches on it; ``bcsdf_sh`` expands the BCSDF in SH (seed 001 §4.3,
the table C_S the precomputed-transport method convolves with); ``bcsdf_sg`` integrates the BCSDF
against a spherical-Gaussian light (seed 001 §5.2.2, Eq. 2 and App. A)."""
