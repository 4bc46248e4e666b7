"""The evaluation protocol (`protocol`), metrics of results.csv (`metrics`), the Dask runner
(`runner`) and the figures + report (`report`) behind `semloc bench`."""

from semloc.eval.protocol import BenchConfig

__all__ = ["BenchConfig"]
