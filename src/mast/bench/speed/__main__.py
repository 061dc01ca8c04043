"""``python -m mast.bench.speed``: the speed benchmark with its defaults."""

from mast.bench.speed.run import run_speed

run_speed()
