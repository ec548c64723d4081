"""Self-tests of the harness's gates: each must pass on the same answer and
refuse a different one (a negative control). Not part of CI; run with
``bench/peers/.venv/bin/python -m unittest discover -s bench/peers`` after
building ``target/release/voxflex``.
"""

from __future__ import annotations

import pathlib
import tempfile
import unittest

import numpy as np
import SimpleITK as sitk

import job_render
import job_resample
import job_roi
from common import Check, Context, Row

REPO = pathlib.Path(__file__).resolve().parent.parent.parent


def context(work: pathlib.Path) -> Context:
    return Context(
        repo=REPO,
        voxflex=REPO / "target/release/voxflex",
        work=work,
        data=REPO.parent / "shared/data",
        repeat=1,
        quick=True,
    )


class Gates(unittest.TestCase):
    def test_a_failed_check_prints_no_ratio(self):
        bad = Row("j", "c", "p", [1.0, 2.0], [3.0, 4.0], Check(False, "w", "v", "t"))
        good = Row("j", "c", "p", [1.0, 2.0], [3.0, 4.0], Check(True, "w", "v", "t"))
        self.assertIsNone(bad.ratio())
        self.assertAlmostEqual(good.ratio(), 3.5 / 1.5)
        self.assertIsNone(Row("j", "c", "goal", [1.0], [], Check(True, "w", "v", "t")).ratio())

    def test_resample_gate_accepts_simpleitk_and_refuses_a_wrong_field(self):
        with tempfile.TemporaryDirectory() as d:
            ctx = context(pathlib.Path(d))
            case = {"label": "t", "source": "phantom:head", "dims": "24,24,20", "angle": 30}
            meta = job_resample.export(ctx, case, "t")
            f, source, reference = job_resample.simpleitk_filter(meta)
            self.assertTrue(job_resample.compare(meta, f.Execute(source), reference).ok)
            # The forward field instead of the backward one: the twist the other way.
            for name in meta["files"]["backward_mm"]:
                path = str(meta["dir"] / name)
                img = sitk.ReadImage(path)
                sitk.WriteImage(-img, path)
            g, _, _ = job_resample.simpleitk_filter(meta)
            self.assertFalse(job_resample.compare(meta, g.Execute(source), reference).ok)

    def test_dice_and_footprint(self):
        a = np.zeros((4, 4, 4), bool)
        a[:2] = True
        self.assertEqual(job_roi.dice(a, a), 1.0)
        self.assertEqual(job_roi.dice(a, ~a), 0.0)
        img = np.zeros((8, 8, 3))
        img[2:6, 2:6] = 0.5
        shifted = np.roll(img, 4, axis=1)
        self.assertEqual(job_render.footprint_iou(img, img), 1.0)
        self.assertLess(job_render.footprint_iou(img, shifted), job_render.IOU_MIN)

    def test_equal_error_takes_each_sides_coarsest_step_within_the_target(self):
        errors = {4.0: 9e-3, 2.0: 4e-3, 1.0: 2e-3, 0.5: 1.5e-3, 0.25: 1e-3}
        self.assertEqual(job_render.equal_error_factor(errors, 2e-3), 1.0)
        self.assertEqual(job_render.equal_error_factor(errors, 5e-3), 2.0)
        self.assertEqual(job_render.equal_error_factor(errors, 1.2e-3), 0.25)
        self.assertIsNone(job_render.equal_error_factor(errors, 5e-4))


if __name__ == "__main__":
    unittest.main()
