"""Job 4: region growing from one seed in the liver of the contrast CT
abdomen phantom, voxflex's spatial opacity map (``voxflex roi``, λ auto and
λ 30) against SimpleITK ``ConnectedThreshold`` and ``ConfidenceConnected``.

The algorithms differ (an opacity map that converges, against a
flood fill in an intensity interval), so "the same thing" is the same
organ: each mask (voxflex's map ≥ 0.5) is scored by Dice against the
phantom's liver label, and a ratio is printed only when voxflex's Dice is
at least the peer's minus ``DICE_SLACK`` and both find the organ
(Dice ≥ ``DICE_FLOOR``) — the issue's goal is speed "at its Dice or better".

Time: voxflex's map alone (``made in … ms``: the automatic λ's scan and the map
written from it, or a fixed λ's growth; not the volume read or the file
write); SimpleITK's ``Execute``.
"""

from __future__ import annotations

import numpy as np
import SimpleITK as sitk

from common import Check, Context, Row, interleave, parse_ms, run_voxflex, timed_ms

LIVER_LABEL = 5  # voxflex_phantom::abdomen::label::LIVER
LIVER_SEED_MM = (-95.0, -10.0, 30.0)  # voxflex_phantom::abdomen::SEEDS, LPS
LIVER_HU, NOISE_HU = 115.0, 15.0  # the phantom's liver value and noise σ
DICE_SLACK = 0.02
DICE_FLOOR = 0.5
# SimpleITK's parameters: ITK's documented examples (ConfidenceConnected:
# multiplier 2.5, 5 iterations, radius 2) and the liver's value ± 2.5 σ.
CC = {"numberOfIterations": 5, "multiplier": 2.5, "initialNeighborhoodRadius": 2, "replaceValue": 1}
CT_WINDOW = (LIVER_HU - 2.5 * NOISE_HU, LIVER_HU + 2.5 * NOISE_HU)


def dice(a: np.ndarray, b: np.ndarray) -> float:
    s = int(a.sum()) + int(b.sum())
    return 2.0 * int(np.logical_and(a, b).sum()) / s if s else 1.0


def sizes(ctx: Context) -> list[str]:
    """The abdomen's resolutions: the ROI front's (3 mm voxels) and, in a
    full run, a CT-like 1.5 mm (7.2 M voxels)."""
    return ["48,38,32"] if ctx.quick else ["120,94,80", "240,188,160"]


def inputs(ctx: Context, dims: str) -> tuple[str, str]:
    d = ctx.case_dir("roi")
    vol, lab = d / f"abdomen_{dims.replace(',', 'x')}.nii", d / f"abdomen_{dims.replace(',', 'x')}_labels.nii"
    if not (vol.exists() and lab.exists()):
        run_voxflex(ctx, "phantom", "abdomen", "--dims", dims, "--out", vol, "--labels", lab)
    return str(vol), str(lab)


def run(ctx: Context) -> list[Row]:
    return [row for dims in sizes(ctx) for row in run_size(ctx, dims)]


def run_size(ctx: Context, dims: str) -> list[Row]:
    vol_path, lab_path = inputs(ctx, dims)
    image = sitk.ReadImage(vol_path)
    truth = sitk.GetArrayFromImage(sitk.ReadImage(lab_path)) == LIVER_LABEL
    seed = image.TransformPhysicalPointToIndex(LIVER_SEED_MM)
    map_path = ctx.case_dir("roi") / "map.nii"
    seed_arg = "--seed=" + ",".join(str(v) for v in LIVER_SEED_MM)

    def voxflex(lam: str):
        def go() -> float:
            out = run_voxflex(ctx, "roi", vol_path, seed_arg, "--lambda", lam, "--out", map_path)
            return parse_ms(r"made in ([\d.]+) ms", out)

        return go

    def voxflex_mask(lam: str) -> np.ndarray:
        voxflex(lam)()
        # The map covers its own box of the volume's voxels: put it back on
        # the whole grid (nearest neighbour is exact: the lattices coincide).
        box = sitk.ReadImage(str(map_path))
        full = sitk.Resample(box, image, sitk.Transform(), sitk.sitkNearestNeighbor, 0.0, box.GetPixelID())
        return sitk.GetArrayFromImage(full) >= 32768  # opacity ≥ 0.5

    peers = {
        "ConfidenceConnected": lambda: sitk.ConfidenceConnected(image, seedList=[seed], **CC),
        "ConnectedThreshold": lambda: sitk.ConnectedThreshold(
            image, seedList=[seed], lower=CT_WINDOW[0], upper=CT_WINDOW[1], replaceValue=1
        ),
    }
    peer_masks = {n: sitk.GetArrayFromImage(f()) > 0 for n, f in peers.items()}  # also the warm-up
    rows = []
    for lam in ("auto", "30"):
        mask = voxflex_mask(lam)
        d_vox = dice(mask, truth)
        sides = [("voxflex", voxflex(lam))] + [(n, (lambda f=f: timed_ms(f)[0])) for n, f in peers.items()]
        times = interleave(ctx.repeat, sides)
        for name in peers:
            d_peer = dice(peer_masks[name], truth)
            ok = d_vox >= d_peer - DICE_SLACK and min(d_vox, d_peer) >= DICE_FLOOR
            rows.append(
                Row(
                    job="roi",
                    case=f"abdomen {'×'.join(map(str, image.GetSize()))}, liver seed, voxflex λ {lam}",
                    peer=f"SimpleITK {sitk.Version_VersionString()} {name}",
                    voxflex_ms=times["voxflex"],
                    peer_ms=times[name],
                    check=Check(
                        ok=ok,
                        what="Dice vs the liver label, voxflex / peer",
                        value=f"{d_vox:.3f} / {d_peer:.3f} (voxflex–peer {dice(mask, peer_masks[name]):.3f})",
                        tolerance=f"voxflex ≥ peer − {DICE_SLACK}, both ≥ {DICE_FLOOR}",
                    ),
                    note=f"{int(truth.sum()):,} liver voxels",
                    extra={"dice_voxflex": d_vox, "dice_peer": d_peer},
                )
            )
    return rows
