"""Running the installed ``mast`` command as a user would: a separate process."""

from __future__ import annotations

import subprocess
import sys

#: A guard against a hang, not a measure of speed: on a loaded two-core machine one
#: ``mast georef`` of the tests took more than 120 s.
HANG_S = 900


def run_mast(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess[bytes]:
    """``python -m mast ARGS`` with its exit status, stdout and stderr (bytes)."""
    return subprocess.run(
        [sys.executable, "-m", "mast", *args],
        capture_output=True,
        input=stdin,
        timeout=HANG_S,
        check=False,
    )


def run_mast_text(*args: str) -> subprocess.CompletedProcess[str]:
    """:func:`run_mast` with stdout and stderr decoded."""
    done = run_mast(*args)
    return subprocess.CompletedProcess(
        done.args, done.returncode, done.stdout.decode(), done.stderr.decode()
    )
