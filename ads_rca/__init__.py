"""ads_rca: root-cause analysis of autonomous-driving crashes, live on ROS 2 or offline."""

import os

__version__ = "0.1.0"

# One BLAS thread, unless the user chose otherwise. Every array ads_rca multiplies holds a
# few dozen numbers, which OpenBLAS's thread pool never speeds up, while its idle threads
# spin after the calls: 9 % of a one-worker diagnose's CPU time, none of its wall time
# (docs/performance.md). Read by OpenBLAS when numpy loads, so set before any ads_rca
# module imports numpy; a process that imported numpy first keeps its pool.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
