"""Several runs at once, one run per task on a Dask cluster (a local one by default).

Each task reads the survey and tracks one bag with :func:`~mast.runs.run.track_run`
into a folder of its own under ``out``; ``index.csv`` lists every run with its
counts, its folder and, for a run that failed, the one-line reason.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from mast.errors import MastError
from mast.io.atomic import atomic_open

__all__ = ["RunOutcome", "expand_runs", "track_runs"]


@dataclass(frozen=True, slots=True)
class RunOutcome:
    """One line of ``index.csv``."""

    run: str
    folder: str
    status: str
    scans: int = 0
    fixes: int = 0
    placed: int = 0
    skipped: int = 0
    elapsed_s: float = 0.0
    error: str = ""


def expand_runs(paths: Sequence[Path]) -> list[Path]:
    """The runs named on the command line: bags, ROS 2 bag folders, folders of scan CSVs,
    or folders holding bags (:func:`mast.io.scans.scan_format` refuses anything else)."""
    from mast.io.scans import scan_format

    out: list[Path] = []
    for p in paths:
        if p.is_dir() and not (p / "metadata.yaml").is_file():
            inner = sorted(
                q
                for q in p.iterdir()
                if (q.is_dir() and (q / "metadata.yaml").is_file())
                or (q.is_file() and q.suffix in (".bag", ".mcap"))
            )
            if inner:
                out.extend(inner)
                continue
        out.append(p)  # a folder of scan CSVs is a run itself
    for run in out:
        scan_format(run, what="run")  # each a run MAST reads, or a clear error now
    return out


def _folder_names(runs: Sequence[Path]) -> list[str]:
    """A distinct output folder name per run (the bag's name, numbered if repeated)."""
    names: list[str] = []
    for r in runs:
        base = r.stem if r.is_file() else r.name
        name, k = base, 2
        while name in names:
            name, k = f"{base}-{k}", k + 1
        names.append(name)
    return names


def _track_one(run: str, survey_path: str, folder: str, options: dict[str, object]) -> RunOutcome:
    """A Dask task: one run, start to finish, in the worker's own process."""
    from mast.io import read_survey
    from mast.report.record import ReportInputs
    from mast.runs.run import track_run
    from mast.runs.track import TrackConfig

    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
        survey = read_survey(survey_path)
        topic = options.get("topic")
        inputs = options.get("inputs")
        result = track_run(
            Path(run),
            survey,
            out,
            config=options.get("config") or TrackConfig(),  # type: ignore[arg-type]
            topic=topic if isinstance(topic, str) else None,
            inputs=inputs if isinstance(inputs, ReportInputs) else None,
            warn=lambda _: None,
        )
    except (MastError, OSError) as err:
        return RunOutcome(run, folder, "error", error=str(err).splitlines()[0][:300])
    s = result.summary
    return RunOutcome(
        run,
        folder,
        "placed" if s.placed else "no_fix",
        s.scans,
        s.fixes,
        s.placed,
        s.skipped,
        round(s.elapsed_s, 3),
    )


def track_runs(
    runs: Sequence[Path],
    survey_path: Path,
    out: Path,
    *,
    options: dict[str, object] | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    echo: Callable[[str], object] = print,
) -> list[RunOutcome]:
    """Track every run in parallel on Dask and write ``out/index.csv``.

    Parameters
    ----------
    runs : sequence of Path
    survey_path : Path
        Read by each worker (a path travels better than a survey object).
    out : Path
        Each run's files go to ``out/<run name>/``.
    options : dict, optional
        ``config`` (TrackConfig), ``topic``, ``inputs`` for every run.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); without it a
        local cluster of processes is started for the call.
    workers : int, optional
        Processes of the local cluster (default: one per run, at most the cores).
    """
    from dask.distributed import Client, LocalCluster, as_completed

    opts = options or {}
    names = _folder_names(runs)
    folders = [str(out / n) for n in names]
    cluster = None
    if scheduler is None:
        n = workers or max(1, min(len(runs), os.cpu_count() or 1))
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None
        )
    client = Client(cluster if cluster is not None else scheduler)  # type: ignore[no-untyped-call]
    outcomes: dict[str, RunOutcome] = {}
    try:
        futures = [
            client.submit(_track_one, str(r), str(survey_path), f, opts, pure=False)
            for r, f in zip(runs, folders, strict=True)
        ]
        for fut in as_completed(futures):  # type: ignore[no-untyped-call]
            o: RunOutcome = fut.result()
            outcomes[o.folder] = o
            tail = o.error if o.status == "error" else f"{o.placed} of {o.scans} scans placed"
            echo(f"{o.run}: {o.status}, {tail} ({len(outcomes)}/{len(runs)})")
    finally:
        client.close()  # type: ignore[no-untyped-call]
        if cluster is not None:
            cluster.close()
    ordered = [outcomes[f] for f in folders]
    with atomic_open(out / "index.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(asdict(ordered[0]).keys()) if ordered else [])
        w.writeheader()
        for o in ordered:
            w.writerow(asdict(o))
    return ordered
