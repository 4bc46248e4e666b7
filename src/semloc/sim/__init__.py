"""Synthetic indoor worlds, an RGB-D sensor by ray casting, detection noise and map variants."""
