"""The procedural stage (seed 000): the realization-minimizing tables build (``tables``), full
realization of every fibre (``realize``) and the brute-force realized reference the lookups are
tested against (``realized_reference``). The yarn model, the tables' layout and the point lookups
that renderers call live in ``stages.core.yarn``."""
