"""The ``mast`` command line.

Each command loads its inputs, calls one library function and prints or saves what it
returns. Errors the library raises on purpose become one line on stderr and an exit
status: 2 bad input, 3 no fix, 4 an output cannot be written, 70 an internal error.

One module a command, each registering on the one application (:mod:`mast.cli.root`) when
imported (``mast --help`` lists them by name); the benchmarks' ``mast bench`` group
and ``mast reproduce`` are registered from above, by :mod:`mast.bench.cli` (the whole
program: :mod:`mast.program`).
"""

from mast.cli import (  # noqa: F401 - imported to register each command
    config,
    demo,
    emulate,
    georef,
    live,
    locate,
    plan,
    ros2,
    scanners,
    simulate,
    survey_in,
    track,
)
from mast.cli.root import app, main

__all__ = ["app", "main"]
