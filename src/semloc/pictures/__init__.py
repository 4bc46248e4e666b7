"""Pictures and 3D recordings, shared by the applications, the simulator's exports and the
evaluation's reports: top-down figures (`viz`, matplotlib), Rerun recordings (`viz3d`), one
colour per label (`colors`) and how user text is shown (`display`).

It sits below the applications (`semloc.tools`, `semloc.cli`) and imports nothing of them;
matplotlib and rerun are imported only by `viz` and `viz3d`.
"""
