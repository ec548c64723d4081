"""voxflex side by side with its peers (issue 17): the same inputs, run
interleaved (A, B, A, B, …), the answers checked equal before any ratio is
printed. Run through ``bench/peers/run.sh`` (it makes the virtual
environment); see ``bench/peers/README.md``.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import os
import pathlib
import shlex
import subprocess
import sys
import time
import traceback

from common import Context, HarnessError, Row, fmt_ms, load_average, machine, min_median

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parent.parent
JOBS = {
    "resample": "job_resample",  # 1 and 2: SimpleITK
    "render": "job_render",  # 3: VTK FixedPoint
    "roi": "job_roi",  # 4: SimpleITK region growing
    "fem": "job_fem",  # 5: scikit-fem
    "springs": "job_springs",  # 6: warp.sim
    "chainmail": "job_chainmail",  # 7: voxflex only, against 0.5 s
}
# The release CLI and the plugins the jobs load.
BUILD = [
    "cargo", "build", "--release", "-p", "voxflex-cli", "-p", "voxflex-raycast",
    "-p", "voxflex-corotational-fem", "-p", "voxflex-affine", "-p", "voxflex-mass-spring",
]  # fmt: skip


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--jobs", default=",".join(JOBS), help=f"comma-separated subset of {','.join(JOBS)}")
    p.add_argument("--repeat", type=int, default=3, help="interleaved rounds per case (≥ 3 for figures; default 3)")
    p.add_argument("--quick", action="store_true", help="tiny sizes: checks the harness in seconds, not the speed")
    p.add_argument("--work", type=pathlib.Path, default=HERE / "work", help="scratch directory (generated inputs)")
    p.add_argument("--out", type=pathlib.Path, default=HERE / "results", help="where results.md / results.json go")
    p.add_argument("--voxflex", type=pathlib.Path, default=REPO / "target/release/voxflex", help="the release CLI")
    p.add_argument("--build", action="store_true", help="run cargo build --release for the CLI and plugins first")
    a = p.parse_args(argv)
    unknown = [j for j in a.jobs.split(",") if j not in JOBS]
    if unknown:
        p.error(f"unknown job(s) {', '.join(unknown)}; choose from {', '.join(JOBS)}")
    if not 1 <= a.repeat <= 100:
        p.error("--repeat must be 1 to 100")
    return a


def ensure_voxflex(a: argparse.Namespace) -> None:
    if a.build or not a.voxflex.exists():
        print("+", " ".join(BUILD), flush=True)
        subprocess.run(BUILD, cwd=REPO, check=True)
    if not a.voxflex.exists():
        raise HarnessError(f"{a.voxflex} does not exist; build it with: {' '.join(BUILD)}")


def versions(ctx: Context) -> dict:
    out = {}
    try:
        out["voxflex"] = subprocess.run([str(ctx.voxflex), "--version"], capture_output=True, text=True).stdout.strip()
        # Which build: others may rebuild target/release while this runs.
        digest = hashlib.sha256(ctx.voxflex.read_bytes()).hexdigest()[:12]
        built = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(ctx.voxflex.stat().st_mtime))
        out["voxflex binary"] = f"sha256 {digest}, built {built}"
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=REPO)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":!bench/peers"],
            capture_output=True, text=True, cwd=REPO,
        ).stdout.strip()  # fmt: skip
        out["git"] = rev.stdout.strip() + (" + uncommitted changes" if dirty else "")
    except OSError as e:
        out["voxflex"] = f"unavailable: {e}"
    for mod, attr in [
        ("SimpleITK", "Version_VersionString"),
        ("vtk", "VTK_VERSION"),
        ("skfem", "__version__"),
        ("scipy", "__version__"),
        ("numpy", "__version__"),
        ("warp", "__version__"),
    ]:
        try:
            m = importlib.import_module(mod)
            v = getattr(m, attr)
            out[mod] = v() if callable(v) else str(v)
        except Exception as e:  # noqa: BLE001 - a missing peer is reported, not fatal
            out[mod] = f"unavailable: {e.__class__.__name__}"
    return out


def cell(text: str) -> str:
    """A markdown table cell: pipes escaped."""
    return str(text).replace("|", "\\|")


def markdown(rows: list[dict], meta: dict) -> str:
    m = meta["machine"]
    quick = " (--quick)" if meta["quick"] else ""
    header = ["job", "case", "peer", "voxflex min / median ms", "peer min / median ms"]
    header += ["peer ÷ voxflex (median)", "same answer?", "note"]
    lines = [
        "# voxflex side by side with its peers",
        "",
        f"Command: `{meta['command']}`  ",
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB, numpy copy {m['copy_bandwidth_gb_s']} GB/s; "
        f"load average {meta['load_before']} before, {meta['load_after']} after  ",
        "Versions: " + ", ".join(f"{k} {v}" for k, v in meta["versions"].items()) + "  ",
        f"Started {meta['started']}; {meta['repeat']} interleaved rounds per case{quick}.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for r in rows:
        c = r["check"]
        ratio = "—" if r["ratio_median"] is None else f"**{r['ratio_median']:.2f}×**"
        if not c["ok"]:
            ratio = "refused (check failed)"
        same = f"{'yes' if c['ok'] else '**no**'}: {c['what']}: {c['value']} (tol. {c['tolerance']})"
        peer = "—" if r["peer_min_ms"] is None else f"{fmt_ms(r['peer_min_ms'])} / {fmt_ms(r['peer_median_ms'])}"
        cells = [
            r["job"],
            r["case"],
            r["peer"],
            f"{fmt_ms(r['voxflex_min_ms'])} / {fmt_ms(r['voxflex_median_ms'])}",
            peer,
            ratio,
            same,
            r["note"],
        ]
        lines.append("| " + " | ".join(cell(c) for c in cells) + " |")
    for f in meta["failures"]:
        lines.append(f"\n**{f['job']} failed:** {f['error']}")
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    a = parse_args(argv)
    ensure_voxflex(a)
    data = pathlib.Path(os.environ.get("VOXFLEX_TEST_DATA", REPO.parent / "shared/data"))
    a.work.mkdir(parents=True, exist_ok=True)
    ctx = Context(
        repo=REPO, voxflex=a.voxflex.resolve(), work=a.work.resolve(), data=data, repeat=a.repeat, quick=a.quick
    )
    meta = {
        "command": "bench/peers/run.sh " + shlex.join(argv),
        "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
        "machine": machine(),
        "versions": versions(ctx),
        "repeat": a.repeat,
        "quick": a.quick,
        "load_before": round(load_average(), 2),
        "failures": [],
    }
    rows: list[Row] = []
    for job in a.jobs.split(","):
        load = round(load_average(), 2)
        print(f"== {job} (load {load})", flush=True)
        try:
            module = importlib.import_module(JOBS[job])
            new = module.run(ctx)
        except (HarnessError, ImportError, subprocess.SubprocessError, OSError, RuntimeError, ValueError) as e:
            traceback.print_exc()
            meta["failures"].append({"job": job, "error": str(e).splitlines()[0][:500]})
            continue
        for r in new:
            vmin, vmed = min_median(r.voxflex_ms)
            pmin, pmed = min_median(r.peer_ms)
            ratio = r.ratio()
            print(
                f"  {r.case}: voxflex {fmt_ms(vmin)} / {fmt_ms(vmed)} ms, {r.peer.split(',')[0]} "
                f"{fmt_ms(pmin)} / {fmt_ms(pmed)} ms, check {'ok' if r.check.ok else 'FAILED'} "
                f"({r.check.value}; tol. {r.check.tolerance})" + (f", ratio {ratio:.2f}×" if ratio is not None else ""),
                flush=True,
            )
        for r in new:
            r.extra["load_before"], r.extra["load_after"] = load, round(load_average(), 2)
            r.note += f" (load {load}–{r.extra['load_after']})"
        rows += new
    meta["load_after"] = round(load_average(), 2)
    summaries = [r.summary() for r in rows]
    a.out.mkdir(parents=True, exist_ok=True)
    md = markdown(summaries, meta)
    (a.out / "results.md").write_text(md)
    (a.out / "results.json").write_text(json.dumps({"meta": meta, "rows": summaries}, indent=1, default=str) + "\n")
    print()
    print(md)
    print(f"wrote {a.out / 'results.md'} and results.json")
    return 1 if meta["failures"] else 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except HarnessError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)
