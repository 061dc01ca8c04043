"""The README's commands run as written, from the repository's root, on the shipped
examples: each ``mast`` line of its ``sh`` blocks, in a temporary folder that holds the
repository's ``examples/`` (so that every output lands there), ends with a documented
exit status (0, or 3 for no fix). The commands run in chains that do not depend on
each other (:func:`readme_chains`), each chain in a folder of its own, so that the test
workers share them.

Left out: the benchmarks and ``mast reproduce`` (minutes each, their own tests), ``mast
live`` from a scanner on the network (``sick://``, ``hokuyo://``; the replay line runs),
and the 10 000-scan drive (its shorter self is tested in tests/test_sim). The ROS 2 pair
(`mast ros2` runs until stopped, `mast emulate ros2` feeds it) runs in a test of its own."""

from __future__ import annotations

import itertools
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests._cli import HANG_S

REPO = Path(__file__).resolve().parents[1]
SKIP = re.compile(
    r"^mast (bench|reproduce)\b|sick://|hokuyo://|--scans 10000|^mast (emulate )?ros2"
)
#: README commands another test runs as written (the same arguments), and that test:
#: run once, there.
ELSEWHERE = {
    "mast demo": "tests/test_cli/test_commands.py::test_demo_prints_the_table2_comparison",
}
#: The options a command writes a file or folder with.
WRITES = ("--out", "--plot", "--record")
#: A file each of these output folders holds when the commands that write it ran.
WRITTEN = {
    "run": "trajectory.csv",
    "all": "index.csv",
    "scans-run": "fixes.jsonl",
    "geo": "transform.json",
    "tls-survey": "beacons.csv",
}


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


def commands_run_here() -> list[str]:
    """The README's commands the test runs: neither left out nor run by another test."""
    return [c for c in readme_commands() if not SKIP.search(c) and c not in ELSEWHERE]


def readme_chains() -> list[list[str]]:
    """The commands the test runs, in chains that do not depend on each other: a command
    that names a path an earlier one wrote (its ``--out``, ``--plot`` or ``--record``),
    or writes where it wrote, runs after it in its chain."""
    chains: list[tuple[set[str], list[str]]] = []
    commands = commands_run_here()
    for command in commands:
        words = shlex.split(command)
        named = {w.rstrip("/").split("/")[0] for w in words if not w.startswith("-")}
        writes = {w.rstrip("/").split("/")[0] for o, w in itertools.pairwise(words) if o in WRITES}
        joined = [c for c in chains if c[0] & named]
        chain: tuple[set[str], list[str]] = (set(writes), [])
        for c in joined:
            chain[0].update(c[0])
            chain[1].extend(c[1])
            chains.remove(c)
        chain[1].append(command)
        chains.append(chain)
    return [sorted(chain, key=commands.index) for _, chain in chains]


def test_the_readme_has_its_commands() -> None:
    commands = readme_commands()
    assert "mast --help" in commands
    assert any(c.startswith("mast locate examples/scan.csv") for c in commands)
    assert any(c.startswith("mast track examples/scans/") for c in commands)
    assert sum(not SKIP.search(c) for c in commands) >= 25


@pytest.mark.parametrize("chain", readme_chains(), ids=lambda chain: " ".join(chain[0].split()[:3]))
def test_every_readme_command_runs_on_the_examples(chain: list[str], tmp_path: Path) -> None:
    """One chain of commands, in order, in a folder of its own."""
    (tmp_path / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    env.pop("MAST_DEBUG", None)
    for command in chain:
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
        # what the command wrote stayed in the temporary folder
        words = shlex.split(command)
        for option, written in itertools.pairwise(words):
            if option in WRITES:
                assert (tmp_path / written).exists(), f"{command}: no {written}"
                folder = written.rstrip("/")
                if folder in WRITTEN:
                    assert (tmp_path / folder / WRITTEN[folder]).is_file(), command
    assert not list((REPO / "examples").glob("**/fixes.jsonl"))


def test_the_readme_chains_keep_every_command_and_its_order() -> None:
    """Every command the test runs is in one chain, each chain in the README's order, and
    a command reading what another wrote is in the writer's chain, after it."""
    commands = commands_run_here()
    chains = readme_chains()
    assert sorted(c for chain in chains for c in chain) == sorted(commands)
    for chain in chains:
        assert [commands.index(c) for c in chain] == sorted(commands.index(c) for c in chain)
    cloud = next(chain for chain in chains if "--scenario cloud" in chain[0])
    assert [c.split()[1] for c in cloud] == ["simulate", "georef", "georef"]
    tls = next(chain for chain in chains if "--scenario tls" in chain[0])
    assert [c.split()[1] for c in tls] == ["simulate", "survey-in"]
    config = next(chain for chain in chains if chain[0].startswith("mast config"))
    assert "--config site.toml" in config[1]
    assert set(WRITTEN) <= {
        w.rstrip("/")
        for c in commands
        for o, w in itertools.pairwise(shlex.split(c))
        if o in WRITES
    }


@pytest.mark.parametrize(("command", "nodeid"), ELSEWHERE.items())
def test_a_readme_command_run_elsewhere_is_run_there(command: str, nodeid: str) -> None:
    """The command is the README's, and the test that runs it exists and runs the
    command's arguments (given as a list to the CLI runner)."""
    import ast
    import inspect

    from tests.conftest import named_test

    assert command in readme_commands()
    test = named_test(nodeid)
    argv = shlex.split(command)[1:]
    source = ast.parse(Path(inspect.getfile(test)).read_text(encoding="utf-8"))
    name = nodeid.split("::")[1]
    (function,) = [f for f in ast.walk(source) if isinstance(f, ast.FunctionDef) and f.name == name]
    lists = [
        ast.literal_eval(node)
        for node in ast.walk(function)
        if isinstance(node, ast.List) and all(isinstance(e, ast.Constant) for e in node.elts)
    ]
    assert callable(test)
    assert argv in lists, f"{nodeid} does not run {argv}"


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
