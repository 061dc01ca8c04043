"""The README's commands run as written, from the repository's root, on the shipped
examples: each ``mast`` line of its ``sh`` blocks, in a temporary folder that holds the
repository's ``examples/`` (so that every output lands there), ends with a documented
exit status (0, or 3 for no fix).

Left out: the benchmarks and ``mast reproduce`` (minutes each, their own tests), ``mast
live`` from a scanner on the network (``sick://``, ``hokuyo://``; the replay line runs),
and the 10 000-scan drive (its shorter self is tested in tests/test_sim). The ROS 2 pair
(`mast ros2` runs until stopped, `mast emulate ros2` feeds it) runs in a test of its own."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests._cli import HANG_S

REPO = Path(__file__).resolve().parents[1]
SKIP = re.compile(
    r"^mast (bench|reproduce)\b|sick://|hokuyo://|--scans 10000|^mast (emulate )?ros2"
)


def readme_commands() -> list[str]:
    """Every command line of the README's ``sh`` blocks that starts with ``mast`` or
    pipes into it, continuation lines joined and comments cut."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    lines: list[str] = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.DOTALL):
        joined = re.sub(r"\\\n\s*", "", block)
        for line in joined.splitlines():
            command = re.sub(r"\s+#.*$", "", line).strip()
            if command.startswith("mast ") or " | mast " in command:
                lines.append(command)
    return lines


def test_the_readme_has_its_commands() -> None:
    commands = readme_commands()
    assert "mast --help" in commands
    assert any(c.startswith("mast locate examples/scan.csv") for c in commands)
    assert any(c.startswith("mast track examples/scans/") for c in commands)
    assert sum(not SKIP.search(c) for c in commands) >= 25


def test_every_readme_command_runs_on_the_examples(tmp_path: Path) -> None:
    (tmp_path / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    env.pop("MAST_DEBUG", None)
    for command in readme_commands():
        if SKIP.search(command):
            continue
        done = subprocess.run(
            command,
            shell=True,
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=HANG_S,
            check=False,
        )
        assert done.returncode in (0, 3), f"{command}: {done.returncode} {done.stderr}"
        assert "Traceback" not in done.stderr, command
    # what the commands wrote stayed in the temporary folder
    assert (tmp_path / "run" / "trajectory.csv").is_file()
    assert (tmp_path / "all" / "index.csv").is_file()
    assert (tmp_path / "scans-run" / "fixes.jsonl").is_file()
    assert (tmp_path / "geo" / "transform.json").is_file()
    assert (tmp_path / "tls-survey" / "beacons.csv").is_file()
    assert not list((REPO / "examples").glob("**/fixes.jsonl"))


def test_the_readme_ros2_pair_runs_as_written(tmp_path: Path) -> None:
    """The node as written (ended by --max-scans), then the bag played as written, in a
    DDS domain of the test's own on loopback."""
    from mast.live.ros2 import LOOPBACK_CONFIG

    commands = readme_commands()
    node_line = next(c for c in commands if c.startswith("mast ros2 "))
    play_line = next(c for c in commands if c.startswith("mast emulate ros2 "))
    (tmp_path / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    env.update(ROS_DOMAIN_ID=str(230 - os.getpid() % 20), CYCLONEDDS_URI=LOOPBACK_CONFIG)
    node = subprocess.Popen(
        f"{node_line} --max-scans 10",
        shell=True,
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert node.stderr is not None
        assert node.stderr.readline().startswith("mast: listening on /scan")
        played = subprocess.run(
            play_line, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True,
            timeout=HANG_S, check=False,
        )  # fmt: skip
        out, err = node.communicate(timeout=HANG_S)
    finally:
        if node.poll() is None:
            node.kill()
    assert played.returncode == 0, played.stderr
    assert node.returncode == 0, err
    assert len(out.splitlines()) >= 1
    assert '"status": "fix"' in out


@pytest.mark.parametrize("folder", ["examples"])
def test_the_examples_are_small(folder: str) -> None:
    files = [p for p in (REPO / folder).rglob("*") if p.is_file()]
    assert sum(p.stat().st_size for p in files) < 1_500_000
