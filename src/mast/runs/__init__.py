"""Survey runs: every scan of a recording placed in the mine grid.

A run is a bag driven through a drift. Each scan is located by the one
pipeline (:mod:`mast.pipeline`), tracked from the previous pose; scans between
fixes are carried by scan-to-scan odometry, and fixes and odometry are
smoothed together in a pose graph. The outputs (trajectory, map, report) are
written by :mod:`mast.runs.outputs`.
"""
