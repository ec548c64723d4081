"""Shared pieces of the side-by-side harness: the run context, running
voxflex, interleaved timing, the equality verdict and the machine record.

Every job module exposes ``run(ctx) -> list[Row]``; ``peers.py`` collects
the rows and prints the table.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import platform
import re
import statistics
import subprocess
import time
from collections.abc import Callable


class HarnessError(RuntimeError):
    """A job could not run (bad input, a tool failed); the message says why."""


@dataclasses.dataclass
class Context:
    """What every job needs; built once by ``peers.py`` from its arguments."""

    repo: pathlib.Path  # repository root
    voxflex: pathlib.Path  # the release CLI
    work: pathlib.Path  # scratch directory for generated inputs and outputs
    data: pathlib.Path  # real volumes (VOXFLEX_TEST_DATA or ../shared/data)
    repeat: int  # interleaved rounds (A, B, A, B, …)
    quick: bool  # tiny sizes: checks the harness, not the speed

    def case_dir(self, *parts: str) -> pathlib.Path:
        d = self.work.joinpath(*parts)
        d.mkdir(parents=True, exist_ok=True)
        return d


@dataclasses.dataclass
class Check:
    """Did both sides compute the same thing? ``ok`` gates the ratio."""

    ok: bool
    what: str  # e.g. "max |Δ| over 1.2 M interior voxels"
    value: str  # the measured figure, formatted
    tolerance: str  # the stated tolerance, formatted


@dataclasses.dataclass
class Row:
    """One line of the table: voxflex against one peer on one case."""

    job: str
    case: str
    peer: str
    voxflex_ms: list[float]
    peer_ms: list[float]  # empty for voxflex-only jobs
    check: Check
    note: str = ""
    extra: dict = dataclasses.field(default_factory=dict)

    def summary(self) -> dict:
        d = dataclasses.asdict(self)
        d["voxflex_min_ms"], d["voxflex_median_ms"] = min_median(self.voxflex_ms)
        d["peer_min_ms"], d["peer_median_ms"] = min_median(self.peer_ms)
        d["ratio_median"] = self.ratio()
        return d

    def ratio(self) -> float | None:
        """Peer median / voxflex median (> 1: voxflex is faster); ``None``
        when the check failed or there is no peer."""
        if not self.check.ok or not self.peer_ms or not self.voxflex_ms:
            return None
        return statistics.median(self.peer_ms) / max(statistics.median(self.voxflex_ms), 1e-9)


def min_median(values: list[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    return min(values), statistics.median(values)


def interleave(repeat: int, sides: list[tuple[str, Callable[[], float]]]) -> dict[str, list[float]]:
    """Runs every side once per round, in order (A, B, A, B, …), ``repeat``
    rounds; each callable returns its own measured time in ms."""
    times: dict[str, list[float]] = {name: [] for name, _ in sides}
    for _ in range(repeat):
        for name, fn in sides:
            times[name].append(fn())
    return times


def timed_ms(fn: Callable[[], object]) -> tuple[float, object]:
    """Wall time of ``fn()`` in ms, and its result."""
    t = time.perf_counter()
    out = fn()
    return (time.perf_counter() - t) * 1e3, out


def run_voxflex(ctx: Context, *args: str, timeout: float = 3600) -> str:
    """Runs the voxflex CLI and returns its standard output; a failure is a
    ``HarnessError`` carrying voxflex's own ``error:`` line."""
    cmd = [str(ctx.voxflex), *map(str, args)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ctx.repo)
    if p.returncode != 0:
        raise HarnessError(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr.strip()[-2000:]}")
    return p.stdout


def bench_executable(ctx: Context, package: str, bench: str) -> pathlib.Path:
    """Builds a crate's bench binary once (``cargo bench --no-run``) and
    returns its path, so the timed rounds run that one binary — no cargo
    check or rebuild between rounds."""
    import json

    cmd = ["cargo", "bench", "--no-run", "-q", "-p", package, "--bench", bench, "--message-format=json"]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ctx.repo, timeout=3600)
    if p.returncode != 0:
        raise HarnessError(f"{' '.join(cmd)} failed: {p.stderr.strip()[-1500:]}")
    for line in p.stdout.splitlines():
        try:
            msg = json.loads(line)
        except json.JSONDecodeError:
            continue
        if (
            msg.get("reason") == "compiler-artifact"
            and msg.get("target", {}).get("name") == bench
            and msg.get("executable")
        ):
            return pathlib.Path(msg["executable"])
    raise HarnessError(f"cargo built no executable for bench `{bench}` of {package}")


def parse_ms(pattern: str, text: str) -> float:
    """The first number captured by ``pattern`` in ``text`` (ms)."""
    m = re.search(pattern, text)
    if not m:
        raise HarnessError(f"no match for /{pattern}/ in voxflex's output:\n{text}")
    return float(m.group(1).replace(",", ""))


def load_average() -> float:
    return os.getloadavg()[0]


def machine() -> dict:
    """CPU model, cores, memory, OS, load average now."""
    model = platform.processor() or "unknown"
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gib = None
    try:
        for line in pathlib.Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem_gib = round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    return {
        "cpu": model,
        "cores": os.cpu_count(),
        "memory_gib": mem_gib,
        "os": platform.platform(),
        "python": platform.python_version(),
        "load_average_1min": round(load_average(), 2),
        "copy_bandwidth_gb_s": copy_bandwidth_gb_s(),
    }


def copy_bandwidth_gb_s(mib: int = 256, repeat: int = 5) -> float:
    """The machine's memory copy bandwidth (read + write bytes per second,
    GB/s): best of ``repeat`` numpy copies of a ``mib`` MiB array."""
    import numpy as np

    src = np.ones(mib * 2**20 // 8)
    dst = np.empty_like(src)
    best = min(timed_ms(lambda: np.copyto(dst, src))[0] for _ in range(repeat))
    return round(2 * src.nbytes / (best * 1e-3) / 1e9, 2)


def fmt_ms(v: float | None) -> str:
    if v is None:
        return "—"
    return f"{v:,.0f}" if v >= 100 else f"{v:.3g}"
