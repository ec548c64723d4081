"""Jobs 1 and 2: resampling a volume under a smooth displacement field,
voxflex against SimpleITK ``ResampleImageFilter`` + ``DisplacementFieldTransform``.

voxflex deforms forward (each source cell's tetrahedra rasterised into
the output grid, then, in ``trilinear`` mode, the trilinear sample of the
source at each output voxel's exact preimage under the piecewise-linear
map). ITK resamples backward: for each output voxel X it samples the
source at X + d(X). ``voxflex resample --export`` writes d — the analytic
map's exact inverse minus X, at every output voxel centre, in LPS mm — on
voxflex's own output grid, so SimpleITK gets the same output grid, the
same field and the same (trilinear) interpolant, and the field is exact at
the voxel centres where it is evaluated (no field interpolation error).

Time: voxflex's resample stage only (its own timer, output already
allocated, the field built before); SimpleITK's ``Execute`` only (the
transform built before).

Equality: |voxflex − SimpleITK| over the output voxels whose preimage lies
≥ 1 voxel inside the source (the outline of the piecewise-linear map and
ITK's border rule differ at the edge by design).
"""

from __future__ import annotations

import json

import numpy as np
import SimpleITK as sitk

from common import Check, Context, HarnessError, Row, interleave, parse_ms, run_voxflex, timed_ms

# Interior voxels must agree to this fraction of the source's value range:
# both sides sample the same trilinear interpolant at the same point in
# (at least) f32; the only differences are f32 rounding of the field and of
# voxflex's rest position (measured: ~1e-6 of the range, see BENCHMARKS.md).
MAX_REL = 1e-4
MEAN_REL = 1e-6


def cases(ctx: Context) -> list[dict]:
    """(label, voxflex source, dims, angle) of each case."""
    colin = ctx.data / "mri_colin27_t1.nii.gz"
    if ctx.quick:
        out = [
            {"label": "head 48³, twist 40°", "source": "phantom:head", "dims": "48,48,48", "angle": 40},
            {"label": "head 64×64×17, twist 30°", "source": "phantom:head", "dims": "64,64,17", "angle": 30},
        ]
    else:
        out = [
            {"label": "head 256³, twist 40°", "source": "phantom:head", "dims": "256,256,256", "angle": 40},
            {"label": "head 512×512×133, twist 30°", "source": "phantom:head", "dims": "512,512,133", "angle": 30},
        ]
    if colin.exists():
        out.append({"label": "Colin27 T1 181×217×181, twist 30°", "source": str(colin), "dims": None, "angle": 30})
    return out


def export(ctx: Context, case: dict, name: str) -> dict:
    """Runs voxflex once with ``--export``; returns resample.json plus the directory."""
    d = ctx.case_dir("resample", name)
    args = ["resample", case["source"], "--field", "twist", "--angle-deg", str(case["angle"]), "--repeat", "1"]
    if case["dims"]:
        args += ["--dims", case["dims"]]
    run_voxflex(ctx, *args, "--export", d)
    meta = json.loads((d / "resample.json").read_text())
    meta["dir"] = d
    return meta


def simpleitk_filter(meta: dict) -> tuple[sitk.ResampleImageFilter, sitk.Image, sitk.Image]:
    """The peer, set up outside the timing: source, field and the output
    grid voxflex chose (taken from voxflex's result image)."""
    d = meta["dir"]
    source = sitk.ReadImage(str(d / meta["files"]["source"]))
    reference = sitk.ReadImage(str(d / meta["files"]["resampled"]))
    parts = [sitk.ReadImage(str(d / f)) for f in meta["files"]["backward_mm"]]
    field = sitk.Cast(sitk.Compose(*parts), sitk.sitkVectorFloat64)
    transform = sitk.DisplacementFieldTransform(field)  # takes the field
    f = sitk.ResampleImageFilter()
    f.SetReferenceImage(reference)
    f.SetTransform(transform)
    f.SetInterpolator(sitk.sitkLinear)
    f.SetDefaultPixelValue(float(meta["background"]))
    f.SetOutputPixelType(sitk.sitkFloat32)
    return f, source, reference


def interior_mask(meta: dict, components: list[np.ndarray], z0: int, z1: int, margin: float = 1.0) -> np.ndarray:
    """Output voxels of slabs z0..z1 whose preimage X + d(X) lies ≥ margin
    source voxels inside the source box (continuous index)."""
    sg, og = meta["source_grid"], meta["output_grid"]
    ox, sp = np.array(og["origin_mm"]), np.array(og["spacing_mm"])
    so, ss, sd = np.array(sg["origin_mm"]), np.array(sg["spacing_mm"]), np.array(sg["dims"])
    k, j, i = np.meshgrid(np.arange(z0, z1), np.arange(og["dims"][1]), np.arange(og["dims"][0]), indexing="ij")
    ok = np.ones(k.shape, bool)
    for axis, idx in enumerate((i, j, k)):
        comp = components[axis][z0:z1]
        pre = (ox[axis] + sp[axis] * idx + comp - so[axis]) / ss[axis]
        ok &= (pre >= margin) & (pre <= sd[axis] - 1 - margin)
    return ok


def compare(meta: dict, peer_out: sitk.Image, reference: sitk.Image) -> Check:
    a = sitk.GetArrayViewFromImage(reference)  # voxflex's result, (z, y, x)
    b = sitk.GetArrayViewFromImage(peer_out)
    # Copies (GetArrayFromImage): a view must not outlive its image.
    src = sitk.GetArrayFromImage(sitk.ReadImage(str(meta["dir"] / meta["files"]["source"])))
    value_range = float(src.max()) - float(src.min())
    del src
    components = [sitk.GetArrayFromImage(sitk.ReadImage(str(meta["dir"] / f))) for f in meta["files"]["backward_mm"]]
    n, total, worst = 0, 0.0, 0.0
    slab = 16
    for z0 in range(0, a.shape[0], slab):
        z1 = min(a.shape[0], z0 + slab)
        m = interior_mask(meta, components, z0, z1)
        diff = np.abs(a[z0:z1][m].astype(np.float64) - b[z0:z1][m])
        if diff.size:
            n += diff.size
            total += float(diff.sum())
            worst = max(worst, float(diff.max()))
    if n == 0:
        raise HarnessError("no output voxel has its preimage inside the source")
    mean = total / n
    ok = worst <= MAX_REL * value_range and mean <= MEAN_REL * value_range
    return Check(
        ok=ok,
        what=f"|Δ| over {n:,} interior voxels (range {value_range:g})",
        value=f"max {worst:.3g}, mean {mean:.2g}",
        tolerance=f"max ≤ {MAX_REL:g}·range, mean ≤ {MEAN_REL:g}·range",
    )


def run_case(ctx: Context, case: dict, name: str) -> Row:
    meta = export(ctx, case, name)
    f, source, reference = simpleitk_filter(meta)
    _, peer_out = timed_ms(lambda: f.Execute(source))  # warm-up; kept for the check
    check = compare(meta, peer_out, reference)
    del peer_out
    src_file = meta["dir"] / meta["files"]["source"]

    def voxflex() -> float:
        out = run_voxflex(
            ctx, "resample", src_file, "--field", "twist", "--angle-deg", str(case["angle"]), "--repeat", "1"
        )
        return parse_ms(r"resample: min ([\d.]+) ms", out)

    def peer() -> float:
        ms, _ = timed_ms(lambda: f.Execute(source))
        return ms

    times = interleave(ctx.repeat, [("voxflex", voxflex), ("peer", peer)])
    og = meta["output_grid"]["dims"]
    out_bytes = 4 * og[0] * og[1] * og[2]  # the f32 output, written once
    best = min(times["voxflex"])
    return Row(
        job="resample",
        case=case["label"],
        peer=f"SimpleITK {sitk.Version_VersionString()} Resample + DisplacementFieldTransform, linear",
        voxflex_ms=times["voxflex"],
        peer_ms=times["peer"],
        check=check,
        note=(
            f"output {og[0]}×{og[1]}×{og[2]} ({out_bytes / 2**20:.0f} MiB f32; voxflex writes it at "
            f"{out_bytes / (best * 1e-3) / 1e9:.2f} GB/s at its best); "
            f"{sitk.ProcessObject.GetGlobalDefaultNumberOfThreads()} ITK threads"
        ),
        extra={"output_dims": og, "source_dims": meta["source_grid"]["dims"]},
    )


def run(ctx: Context) -> list[Row]:
    return [run_case(ctx, c, f"case{i}") for i, c in enumerate(cases(ctx))]
