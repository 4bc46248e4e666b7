"""semloc's applications on top of the core: the demo (`demo`, `scandemo`), pictures and 3D
recordings (`viz`, `viz3d`), how labels and user text are shown (`colors`, `display`), and
loading the compiled code before timed work (`warmup`).

The package's top level is the core (pure computation on numpy arrays); everything here may
do I/O, plotting or simulation.  Heavy extras (matplotlib, rerun) are imported only where used.
"""
