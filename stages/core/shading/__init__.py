"""Scattering models, each with eval / pdf / sample: the fibre BCSDF (``bcsdf``), a Lambertian
surface (``lambert``), the SGGX micro-flake phase function (``sggx``); ``material`` packs a model and
its parameters into one row and dispatches on it."""
