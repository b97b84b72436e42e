"""Shell-mapped tiled exemplars (seed 001 §5.1): ``scene`` builds a ``ShellScene`` from a tiling
artifact's arrays, ``traversal`` walks rays through the shell's tetrahedra into the exemplars."""
