"""semloc's applications on top of the core: the demo (`demo`, `scandemo`) and merging two
aligned maps (`merge`).

The package's top level is the core (pure computation on numpy arrays); everything here may
do I/O, plotting or simulation.  The pictures they draw are `semloc.pictures`; the compiled
code is warmed up by `semloc.compiling`.  The modules `colors`, `display`, `viz`, `viz3d` and
`warmup` that lived here are those (each name here is the moved module itself).
"""
