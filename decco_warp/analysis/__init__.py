"""Analysis of snapshots and runs (paper sect. 2.7 and 4): NumPy and SciPy, no Warp kernels."""

from .clusters import Cluster, find_clusters

__all__ = ["Cluster", "find_clusters"]
