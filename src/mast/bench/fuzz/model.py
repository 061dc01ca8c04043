"""What a fuzz case is, what it gave, and the tally: the bounds each case is judged by."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "AGREE_SIGMAS",
    "DOCUMENTED",
    "MEMORY_BOUND_BYTES",
    "SAME_AZIMUTH_ARCSEC",
    "SAME_POSITION_M",
    "TIME_FACTOR",
    "FuzzCase",
    "FuzzResult",
    "FuzzSummary",
]


#: Exit statuses ``mast`` documents (success, bad input, no fix, cannot write).
DOCUMENTED = frozenset({0, 2, 3, 4})
#: The memory bound: 1 GiB, or twice the undamaged run's peak if that is larger.
MEMORY_BOUND_BYTES = 1 << 30
#: A damaged run may take this many times the undamaged run's time (plus a second).
TIME_FACTOR = 10.0
#: A fix differs from the undamaged one beyond this many combined standard deviations ...
AGREE_SIGMAS = 5.0
#: ... and these.
SAME_POSITION_M = 1e-3
SAME_AZIMUTH_ARCSEC = 1.0


@dataclass(frozen=True, slots=True)
class FuzzCase:
    """One run of ``mast``: its family, what was done to the input, the arguments, and
    the seed whose undamaged run it is judged against (None for output-path cases)."""

    family: str
    mutation: str
    argv: tuple[str, ...]
    seed: str | None
    expect: frozenset[int] = DOCUMENTED
    file_limit: int | None = None
    stdout: str | None = None  # "full" (/dev/full) or "closed" (a pipe closed at once)
    outputs: tuple[str, ...] = ()  # targets that must not be left half-written


@dataclass(frozen=True, slots=True)
class FuzzResult:
    case: FuzzCase
    status: int
    seconds: float
    peak_bytes: int
    stderr: str
    stdout: str
    problems: tuple[str, ...]


@dataclass(slots=True)
class FuzzSummary:
    cases: int = 0
    by_family: dict[str, int] = field(default_factory=dict)
    by_status: dict[int, int] = field(default_factory=dict)
    tracebacks: int = 0
    undocumented: int = 0
    not_one_line: int = 0
    over_memory: int = 0
    over_time: int = 0
    wrong_fixes: int = 0
    half_written: int = 0
    unexpected_status: int = 0
    peak_bytes: int = 0  # a case's own peak, above what it inherited
    inherited_bytes: int = 0  # the resident memory a child starts with (the largest)
    worst_time_ratio: float = 0.0
    seconds: float = 0.0
    failures: list[FuzzResult] = field(default_factory=list)
    slowest: list[tuple[float, str]] = field(default_factory=list)

    @property
    def failed(self) -> int:
        return len(self.failures)

    def line(self) -> str:
        statuses = ", ".join(f"{k}: {v}" for k, v in sorted(self.by_status.items()))
        return (
            f"{self.cases} inputs ({len(self.by_family)} families) in {self.seconds:.0f} s: "
            f"failures {self.failed} (tracebacks {self.tracebacks}, undocumented status "
            f"{self.undocumented}, not one line {self.not_one_line}, over memory "
            f"{self.over_memory}, over time {self.over_time}, fixes differing {self.wrong_fixes}, "
            f"half-written outputs {self.half_written}, unexpected status "
            f"{self.unexpected_status}); exit statuses {{{statuses}}}; peak memory "
            f"{self.peak_bytes / 2**20:.0f} MiB above the {self.inherited_bytes / 2**20:.0f} MiB "
            f"a child inherits; worst time {self.worst_time_ratio:.1f}x undamaged"
        )
