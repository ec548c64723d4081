"""Job 3: 512² shaded direct volume rendering of a 512×512×133 CT-class
volume, voxflex's ``raycast`` plugin (CPU) against VTK's
``vtkFixedPointVolumeRayCastMapper`` (CPU; off screen through EGL).

Same inputs: the head phantom written once to NIfTI (``voxflex phantom``),
read by voxflex and, through SimpleITK, handed to VTK as image data in the
same LPS millimetres. Same settings: the ``ct-bone`` transfer function's
control points (colour and opacity per 1 mm, ``ScalarOpacityUnitDistance``
= 1), Phong shading ambient 0.1 / diffuse 0.9 / specular 0.2 / power 10
with a headlight, trilinear sampling, the same ray step in mm, and voxflex's
orthographic camera (``visualise::camera_for``: azimuth 30°, elevation 15°,
target the volume's centre, view height the diagonal of its voxel-centre
box, z up).

Same thing: the renderers differ by design (VTK composites the TF colours
as given with 8-bit quantised normals; voxflex composites in linear light
with Sobel gradients), so pixels are not compared across renderers.
Instead (a) the *footprint* — pixels brighter than ``FOOTPRINT`` of full
scale — must agree (IoU ≥ ``IOU_MIN``: same camera, same TF opacity), and
(b) each renderer's image error is measured against its *own* converged
reference, the same view at 1/``REF_DIVISOR`` of the step (RMS over R, G, B
in [0, 1], over black), and both errors are reported beside the ratio;
(c) the "equal error" row sets the error target to the *worse* of the two
errors at the common step, then times each renderer at the largest step
of ``STEP_FACTORS`` × that step whose error against its own reference is
within the target (both sides swept the same way, so the better renderer
may take a coarser step and the worse one a finer step).

Times: the steady frame (voxflex ``render --repeat``: rays only, the
volume already handed over; VTK ``Render()`` after the first) and the
first frame (voxflex: hand-over, macro cells and rays; VTK: the first
``Render()``, its gradient encoding included).
"""

from __future__ import annotations

import os
import re

import numpy as np
import SimpleITK as sitk

from common import Check, Context, HarnessError, Row, interleave, parse_ms, run_voxflex, timed_ms

CT_BONE = [  # plugins/raycast/src/transfer.rs: value (HU), sRGB, alpha per 1 mm
    (-1000.0, 0.0, 0.0, 0.0, 0.0),
    (150.0, 0.55, 0.25, 0.15, 0.0),
    (300.0, 0.85, 0.65, 0.45, 0.3),
    (700.0, 0.95, 0.88, 0.75, 0.6),
    (1500.0, 1.0, 1.0, 0.95, 0.85),
    (3071.0, 1.0, 1.0, 1.0, 0.9),
]
AZIMUTH, ELEVATION = 30.0, 15.0
STEP_VOXELS = 0.5  # voxflex's default sample_distance
REF_DIVISOR = 8  # the reference's step: STEP / 8
STEP_FACTORS = (4.0, 2.0, 1.0, 0.5, 0.25)  # steps tried for the equal-error row, coarsest first
FOOTPRINT = 0.05
IOU_MIN = 0.9


def camera(img: sitk.Image) -> dict:
    """voxflex's default orthographic camera for this grid (see camera.rs)."""
    size = np.array(img.GetSize(), float)
    spacing, origin = np.array(img.GetSpacing()), np.array(img.GetOrigin())
    lo, hi = origin, origin + (size - 1) * spacing
    diagonal = max(float(np.linalg.norm(hi - lo)), 1.0)
    target = 0.5 * (lo + hi)
    az, el = np.radians(AZIMUTH), np.radians(ELEVATION)
    to_eye = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
    return {"target": target, "eye": target + to_eye * 2 * diagonal, "height_mm": diagonal}


class VtkRenderer:
    """The peer: one off-screen window, mapper and volume, set up once."""

    def __init__(self, img: sitk.Image, size: int, step_mm: float):
        import vtk
        from vtk.util import numpy_support

        self.vtk = vtk
        arr = sitk.GetArrayFromImage(img)  # (z, y, x): C order is x fastest, as VTK wants
        data = vtk.vtkImageData()
        data.SetDimensions(*img.GetSize())
        data.SetSpacing(*img.GetSpacing())
        data.SetOrigin(*img.GetOrigin())
        if np.abs(np.array(img.GetDirection()) - np.eye(3).ravel()).max() > 1e-9:
            raise HarnessError("the volume must have identity direction (voxflex writes it so)")
        scalars = numpy_support.numpy_to_vtk(arr.ravel(), deep=True)
        data.GetPointData().SetScalars(scalars)
        self.data = data
        color, opacity = vtk.vtkColorTransferFunction(), vtk.vtkPiecewiseFunction()
        for v, r, g, b, a in CT_BONE:
            color.AddRGBPoint(v, r, g, b)
            opacity.AddPoint(v, a)
        prop = vtk.vtkVolumeProperty()
        prop.SetColor(color)
        prop.SetScalarOpacity(opacity)
        prop.SetScalarOpacityUnitDistance(1.0)
        prop.SetInterpolationTypeToLinear()
        prop.ShadeOn()
        prop.SetAmbient(0.1)
        prop.SetDiffuse(0.9)
        prop.SetSpecular(0.2)
        prop.SetSpecularPower(10.0)
        self.mapper = vtk.vtkFixedPointVolumeRayCastMapper()
        self.mapper.SetInputData(data)
        self.mapper.SetAutoAdjustSampleDistances(0)
        self.mapper.SetLockSampleDistanceToInputSpacing(0)
        self.mapper.SetImageSampleDistance(1.0)
        self.mapper.SetSampleDistance(step_mm)
        volume = vtk.vtkVolume()
        volume.SetMapper(self.mapper)
        volume.SetProperty(prop)
        self.ren = vtk.vtkRenderer()
        self.ren.SetBackground(0, 0, 0)
        self.ren.AddVolume(volume)
        self.win = vtk.vtkRenderWindow()
        self.win.SetOffScreenRendering(1)
        self.win.SetSize(size, size)
        self.win.AddRenderer(self.ren)
        cam = camera(img)
        c = self.ren.GetActiveCamera()
        c.SetFocalPoint(*cam["target"])
        c.SetPosition(*cam["eye"])
        c.SetViewUp(0, 0, 1)
        c.ParallelProjectionOn()
        c.SetParallelScale(cam["height_mm"] / 2)
        self.ren.ResetCameraClippingRange()

    def set_step(self, step_mm: float) -> None:
        self.mapper.SetSampleDistance(step_mm)

    def frame_ms(self) -> float:
        self.ren.GetActiveCamera().Modified()  # a new frame, as an orbit would ask
        ms, _ = timed_ms(self.win.Render)
        return ms

    def image(self) -> np.ndarray:
        """RGB in [0, 1], top row first."""
        from vtk.util import numpy_support

        grab = self.vtk.vtkWindowToImageFilter()
        grab.SetInput(self.win)
        grab.SetInputBufferTypeToRGB()
        grab.ReadFrontBufferOff()
        grab.Update()
        out = grab.GetOutput()
        w, h, _ = out.GetDimensions()
        rgb = numpy_support.vtk_to_numpy(out.GetPointData().GetScalars()).reshape(h, w, 3)
        return rgb[::-1].astype(np.float64) / 255.0


def voxflex_image(path) -> np.ndarray:
    """RGB over black in [0, 1] from voxflex's RGBA PNG (straight alpha)."""
    rgba = sitk.GetArrayFromImage(sitk.ReadImage(str(path))).astype(np.float64) / 255.0
    return rgba[..., :3] * rgba[..., 3:4]


def rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def footprint_iou(a: np.ndarray, b: np.ndarray) -> float:
    fa, fb = a.max(axis=2) > FOOTPRINT, b.max(axis=2) > FOOTPRINT
    union = np.logical_or(fa, fb).sum()
    return float(np.logical_and(fa, fb).sum() / union) if union else 1.0


def equal_error_factor(errors: dict[float, float], target: float) -> float | None:
    """The coarsest step factor whose error is within ``target`` (``None``
    when no factor tried is)."""
    return next((f for f in STEP_FACTORS if errors[f] <= target), None)


def run(ctx: Context) -> list[Row]:
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    d = ctx.case_dir("render")
    dims, size = ("96,96,25", 128) if ctx.quick else ("512,512,133", 512)
    vol = d / f"head_{dims.replace(',', 'x')}.nii"
    if not vol.exists():
        run_voxflex(ctx, "phantom", "head", "--dims", dims, "--out", vol)
    img = sitk.ReadImage(str(vol))
    step_mm = STEP_VOXELS * min(img.GetSpacing())
    common = ["render", vol, "--size", f"{size}x{size}", "--backend", "cpu", "--preset", "ct-bone"]
    common += ["--azimuth", str(AZIMUTH), "--elevation", str(ELEVATION)]

    # References: each renderer at a step REF_DIVISOR times smaller.
    run_voxflex(ctx, *common, "--step", str(STEP_VOXELS / REF_DIVISOR), "--out", d / "voxflex_ref.png")
    vref = voxflex_image(d / "voxflex_ref.png")
    peer = VtkRenderer(img, size, step_mm / REF_DIVISOR)
    peer.frame_ms()  # the first frame, at the reference step
    tref = peer.image()
    # Each renderer at every step factor (voxflex's common-step run is also
    # its warm-up): errors against its own reference.
    e_vox_by, e_vtk_by, vtk_images = {}, {}, {}
    for f in STEP_FACTORS:
        out = d / f"voxflex_x{f:g}.png"
        run_voxflex(ctx, *common, "--step", str(STEP_VOXELS * f), "--out", out)
        e_vox_by[f] = rms(voxflex_image(out), vref)
        peer.set_step(step_mm * f)
        peer.frame_ms()
        vtk_images[f] = peer.image()
        e_vtk_by[f] = rms(vtk_images[f], tref)
    e_vox, e_vtk, timg = e_vox_by[1.0], e_vtk_by[1.0], vtk_images[1.0]
    target = max(e_vox, e_vtk)
    f_vox, f_vtk = equal_error_factor(e_vox_by, target), equal_error_factor(e_vtk_by, target)
    peer.set_step(step_mm)
    peer_eq = VtkRenderer(img, size, step_mm * (f_vtk or 1.0))
    peer_eq.frame_ms()

    first: dict[str, list[float]] = {"voxflex": [], "peer": []}

    def voxflex() -> float:
        out = run_voxflex(ctx, *common, "--step", str(STEP_VOXELS), "--repeat", "1", "--out", d / "voxflex.png")
        first["voxflex"].append(parse_ms(r"in ([\d.]+) ms", out))
        m = re.search(r"repeat frames \(ms\): ([\d.]+)", out)
        if not m:
            raise HarnessError(f"no repeat frame in voxflex's output:\n{out}")
        return float(m.group(1))

    def voxflex_eq() -> float:
        out = run_voxflex(
            ctx, *common, "--step", str(STEP_VOXELS * (f_vox or 1.0)), "--repeat", "1", "--out", d / "voxflex_eq.png"
        )
        m = re.search(r"repeat frames \(ms\): ([\d.]+)", out)
        if not m:
            raise HarnessError(f"no repeat frame in voxflex's output:\n{out}")
        return float(m.group(1))

    def vtk_first() -> float:
        fresh = VtkRenderer(img, size, step_mm)
        ms = fresh.frame_ms()
        first["peer"].append(ms)
        del fresh
        return peer.frame_ms()

    sides = [("voxflex", voxflex), ("peer", vtk_first), ("voxflex_eq", voxflex_eq), ("peer_eq", peer_eq.frame_ms)]
    times = interleave(ctx.repeat, sides)
    vimg = voxflex_image(d / "voxflex.png")
    for name, im in [("vtk.png", timg), ("vtk_ref.png", tref)]:
        sitk.WriteImage(sitk.GetImageFromArray((im * 255).round().astype(np.uint8), isVector=True), str(d / name))
    iou = footprint_iou(vimg, timg)
    import vtk

    check = Check(
        ok=iou >= IOU_MIN,
        what=f"footprint IoU (pixels > {FOOTPRINT}); RMS error vs own step/{REF_DIVISOR} reference, voxflex / VTK",
        value=f"IoU {iou:.3f}; error {e_vox:.2e} / {e_vtk:.2e}; cross RMS of the references {rms(vref, tref):.3f}",
        tolerance=f"IoU ≥ {IOU_MIN}",
    )
    check_eq = Check(
        ok=iou >= IOU_MIN and f_vox is not None and f_vtk is not None,
        what="footprint IoU; each side at its coarsest step within the worse common-step error",
        value=(
            f"IoU {iou:.3f}; target {target:.2e}; voxflex step × {f_vox} ({e_vox_by.get(f_vox, float('nan')):.2e}), "
            f"VTK step × {f_vtk} ({e_vtk_by.get(f_vtk, float('nan')):.2e})"
        ),
        tolerance=f"IoU ≥ {IOU_MIN}, both errors ≤ the target",
    )
    case = f"head {dims.replace(',', '×')}, {size}² ct-bone shaded, step {step_mm:.3g} mm"
    peer_name = f"VTK {vtk.vtkVersion.GetVTKVersion()} vtkFixedPointVolumeRayCastMapper"
    sweep_note = "; ".join(
        f"step × {f:g}: voxflex {e_vox_by[f]:.2e}, VTK {e_vtk_by[f]:.2e}" for f in STEP_FACTORS
    )
    return [
        Row("render", case + ", steady frame, same step", peer_name, times["voxflex"], times["peer"], check,
            note=f"image error voxflex {e_vox:.2e}, VTK {e_vtk:.2e}",
            extra={"error_voxflex": e_vox, "error_vtk": e_vtk, "iou": iou}),
        Row("render", case + f", steady frame, equal error (voxflex step × {f_vox})", f"{peer_name} at step × {f_vtk}",
            times["voxflex_eq"], times["peer_eq"], check_eq,
            note=f"error by step: {sweep_note}",
            extra={"target": target, "voxflex_sweep": e_vox_by, "vtk_sweep": e_vtk_by,
                   "voxflex_factor": f_vox, "vtk_factor": f_vtk}),
        Row("render", case + ", first frame", peer_name, first["voxflex"], first["peer"], check,
            note="voxflex: hand-over + first image + PNG; VTK: first Render() of a new mapper"),
    ]  # fmt: skip
