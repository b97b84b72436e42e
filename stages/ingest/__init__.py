"""Ingest stage kernels: weave and knit generators, yarn-curve processing."""
