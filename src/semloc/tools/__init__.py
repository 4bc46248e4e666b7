"""semloc's applications on top of the core: the demo (`demo`, `scandemo`) and merging two
aligned maps (`merge`).

The package's top level is the core (pure computation on numpy arrays); everything here may
do I/O, plotting or simulation.  The pictures they draw are `semloc.pictures`; the compiled
code is warmed up by `semloc.compiling`.
"""
