"""``--config FILE.toml``: the settings a command that locates reads, the effective
configuration it runs with (the file, then the options given on the command line), and
that configuration's fingerprint, which every JSON record names and ``config.toml``
beside a run's results holds (:mod:`mast.io.settings`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from mast import __version__
from mast.errors import InputError
from mast.io.settings import fingerprint, from_table, read_settings, settings_text

if TYPE_CHECKING:
    from mast.core.beacon import Survey
    from mast.io.crs import GridCrs
    from mast.pipeline.locator import LocatorConfig
    from mast.report.record import ReportInputs

__all__ = [
    "COMMAND_TABLES",
    "ConfigOption",
    "Effective",
    "effective",
    "locator_settings",
    "read_config",
    "report_inputs",
]

ConfigOption = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="Settings file (TOML: [locator] and its sub-tables; [track] or [sequence]); "
        "options given on the command line override it. `mast config` prints one.",
    ),
]

#: The tables each command that locates reads (a settings file may hold any of them).
COMMAND_TABLES: dict[str, tuple[str, ...]] = {
    "locate": ("locator", "sequence"),
    "track": ("locator", "track"),
    "live": ("locator", "sequence"),
    "ros2": ("locator", "sequence"),
}


def _classes() -> dict[str, type]:
    """Every table a settings file may hold, in the order they are written, and the
    configuration each is read onto."""
    from mast.pipeline.locator import LocatorConfig, SequenceConfig
    from mast.runs.track import TrackConfig

    return {"locator": LocatorConfig, "track": TrackConfig, "sequence": SequenceConfig}


def read_config(path: Path | None, command: str) -> tuple[dict[str, Any], set[str]]:
    """The configurations ``command`` reads (:data:`COMMAND_TABLES`) from the settings
    file at ``path`` (defaults for a table it leaves out, or without a file), and the
    ``table.key`` names it set."""
    classes = _classes()
    tables = COMMAND_TABLES[command]
    if path is None:
        return {name: classes[name]() for name in tables}, set()
    data, text = read_settings(path)
    known = tuple(classes)
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise InputError(f"no settings table [{unknown[0]}]; known: {', '.join(known)}", path=path)
    out: dict[str, Any] = {}
    given: set[str] = set()
    # Every table the file holds is checked (a mistake in one this command does not use
    # would surface in the next command); only the command's own are returned.
    for name in sorted(set(tables) | set(data), key=known.index):
        table = data.get(name, {})
        if not isinstance(table, dict):
            raise InputError(f"{name} must be a table: [{name}]", path=path)
        if name == "track" and "locator" in table:
            raise InputError("the locator's settings are [locator], not [track.locator]", path=path)
        read: Any = from_table(classes[name], table, path=path, text=text, where=name)
        if name in tables:
            out[name] = read
            given |= {f"{name}.{key}" for key in table}
    return out, given


@dataclass(frozen=True)
class Effective:
    """The configuration a command runs with: its TOML text (a comment, then the
    canonical settings) and the SHA-256 of the settings."""

    text: str
    sha256: str

    def write(self, path: Path) -> None:
        """Write the settings file (``config.toml`` beside a run's results: the run given
        it with ``--config`` gives the same results)."""
        from mast.io.atomic import write_atomic

        write_atomic(path, self.text.encode("utf-8"))


def effective(tables: Mapping[str, Any], command: str) -> Effective:
    """The effective configuration of ``command`` (``track``'s locator is ``[locator]``)."""
    body = settings_text(tables, skip=("locator",))
    header = (
        f"# The settings of `mast {command}` (mast {__version__}): --config runs with them.\n"
        f"# SHA-256 of the settings below: {fingerprint(body)}\n"
    )
    return Effective(header + body, fingerprint(body))


def locator_settings(
    command: str,
    config: Path | None,
    precision: tuple[float | None, float | None, str | None, float | None],
    *,
    angle_sigma_deg: float | None = None,
) -> tuple[dict[str, Any], LocatorConfig, set[str]]:
    """A locating command's ``--config`` tables, its locator's settings (the file's, then
    the precisions given: range sigma, the old ``--angle-sigma`` in radians, scanner,
    survey sigma, and ``--angle-sigma-deg``) and the precisions left at their defaults
    (:func:`mast.cli.options.precisions`)."""
    from mast.cli.options import precisions

    range_sigma, angle_sigma, scanner, survey_sigma = precision
    tables, given = read_config(config, command)
    cfg, defaults = precisions(
        range_sigma,
        angle_sigma,
        scanner,
        survey_sigma,
        angle_sigma_deg=angle_sigma_deg,
        base=tables["locator"],
        given=given,
    )
    return tables, cfg, defaults


def report_inputs(
    *,
    beacons: Path,
    survey: Survey,
    locator: LocatorConfig,
    scanner: str | None,
    defaults: set[str],
    config: Path | None,
    settings: Effective,
    crs: GridCrs | None,
    scan_file: str | None = None,
    topic: str | None = None,
) -> ReportInputs:
    """What each record and report of a locating command states about its inputs."""
    from mast.report.record import ReportInputs, survey_weighing

    return ReportInputs(
        scan_file=scan_file,
        survey_file=str(beacons),
        scanner=scanner,
        topic=topic,
        defaults=frozenset(defaults),
        config_file=None if config is None else str(config),
        config_sha256=settings.sha256,
        survey_sigmas=survey_weighing(survey, locator.survey_sigma_m),
        crs=crs,
    )
