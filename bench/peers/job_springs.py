"""Job 6: one explicit mass-spring sub-step, voxflex against Warp's
``warp.sim`` ``SemiImplicitIntegrator`` on the CPU.

The network: the nodes of a 32 × 32 × 16-cell box at 2 mm (18,513 nodes),
springs on the edges of each cell's five-tetrahedra split (the twelve
cube edges and one diagonal per face: 104,528 springs), the face x = 0
fixed, gravity −9810 mm/s². voxflex's side is a scene run through the CLI
(``voxflex run``): a block volume whose voxel centres are those nodes, the
``mass-spring`` plugin on its uniform proxy (step 1), ``integrator =
"explicit"``, volume springs off — springs only, like Warp's. Warp gets
the same nodes and the edges of tests/reference/cantilever.py's split.

(``cargo bench -p voxflex-mass-spring -- substep`` no longer measures an
explicit sub-step: its model takes ``SpringParams::default()``, whose
integrator is now implicit, so it prints one implicit step per "frame of
1 sub-steps".)

Same thing: the same network (nodes; tetrahedra, whose edges are the
springs) under the same kind of integrator (symplectic Euler, damped
springs, gravity). The spring constants are derived differently (voxflex
from E and ν, Warp given one ke), which changes numbers but not the work
per sub-step, so the check is the network and that Warp's state stays
finite — not a trajectory.

Time: per sub-step, voxflex's model stage wall time over its sub-steps
(2–5 frames of 0.05 s; the per-frame work — dirty region, binding — is
included, so this slightly favours Warp); Warp's median over 5 frames of
``SUBSTEPS`` sub-steps.
"""

from __future__ import annotations

import json
import os
import pathlib
import time

import numpy as np
import SimpleITK as sitk

from common import Check, Context, HarnessError, Row, interleave, run_voxflex

CELLS = (32, 32, 16)
SPACING_MM = 2.0
SUBSTEPS = 50
CELL_EDGES = [  # corner pairs (c = cx + 2 cy + 4 cz) of each cell's split, by parity
    [(0, 1), (0, 2), (0, 4), (1, 3), (1, 5), (2, 3), (2, 6), (3, 7), (4, 5), (4, 6), (5, 7), (6, 7),
     (1, 2), (1, 4), (2, 4), (1, 7), (2, 7), (4, 7)],
    [(0, 1), (0, 2), (0, 4), (1, 3), (1, 5), (2, 3), (2, 6), (3, 7), (4, 5), (4, 6), (5, 7), (6, 7),
     (0, 3), (0, 5), (0, 6), (3, 5), (3, 6), (5, 6)],
]  # fmt: skip


def network() -> tuple[np.ndarray, np.ndarray]:
    """Node positions (mm) and unique spring edges of the box."""
    nx, ny, nz = CELLS
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    pos = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1).astype(np.float64) * SPACING_MM

    def node(a, b, c):
        return a + (nx + 1) * (b + (ny + 1) * c)

    edges = []
    for ck in range(nz):
        for cj in range(ny):
            for ci in range(nx):
                corner = [node(ci + (c & 1), cj + ((c >> 1) & 1), ck + (c >> 2)) for c in range(8)]
                edges += [(corner[a], corner[b]) for a, b in CELL_EDGES[(ci + cj + ck) & 1]]
    e = np.sort(np.array(edges), axis=1)
    return pos, np.unique(e, axis=0)


SCENE = """[scene]
name = "peers-springs"
backend = "cpu"
frames = {frames}
dt_s = 0.05

[volume]
source = "{volume}"

[model]
plugin = "mass-spring"

[model.params.mass-spring]
proxy = {{ kind = "uniform", step = 1 }}
materials = [{{ name = "block", range = [50, 150], youngs_modulus = 3000, poisson_ratio = 0.45 }}]
integrator = "explicit"
gravity = [0, 0, -9810]
volume_stiffness = 0

[[interaction]]
frame = 0
kind = "fix"
min = [-1, -1, -1]
max = [0.5, 65, 33]

[output]
dir = "{out}"
slices = []
"""


def voxflex_scene(ctx: Context) -> pathlib.Path:
    """A block volume whose voxel centres are the box's nodes, and the
    scene that runs the mass-spring plugin on it (explicit, springs only)."""
    d = ctx.case_dir("springs")
    nx, ny, nz = CELLS
    img = sitk.GetImageFromArray(np.full((nz + 1, ny + 1, nx + 1), 100, np.uint8))
    img.SetSpacing((SPACING_MM,) * 3)
    sitk.WriteImage(img, str(d / "block.nii"))
    scene = d / "springs.toml"
    scene.write_text(SCENE.format(frames=2 if ctx.quick else 5, volume=d / "block.nii", out=d / "out"))
    return scene


def voxflex_substep(ctx: Context, scene: pathlib.Path) -> tuple[float, dict]:
    """One ``voxflex run``: ms per explicit sub-step (the model stage's wall
    time over its sub-steps) and the model's notes."""
    run_voxflex(ctx, "run", scene, "--force")
    m = json.loads((scene.parent / "out/metrics.json").read_text())
    model = m["stages"]["model"]
    notes = model["notes"]
    if not notes.get("substeps"):
        raise HarnessError(f"the mass-spring model reported no sub-steps: {notes}")
    return model["wall_ms"] / notes["substeps"], notes


class WarpSprings:
    """The same network in warp.sim on the CPU."""

    def __init__(self, pos: np.ndarray, edges: np.ndarray):
        import warp as wp
        import warp.sim

        wp.config.quiet = True
        wp.init()
        self.wp = wp
        b = warp.sim.ModelBuilder(gravity=-9810.0, up_vector=(0.0, 0.0, 1.0))
        mass = 1e-6 * SPACING_MM**3  # kg: 1e-6 kg/mm³ (water) per node's cell
        for p in pos:
            b.add_particle(tuple(p), (0.0, 0.0, 0.0), 0.0 if p[0] <= 0.5 else mass, radius=0.1)
        ke = 3000.0 * SPACING_MM * 1e-3  # N/mm, E·L for E = 3 kPa (as voxflex's bench)
        for a, c in edges:
            b.add_spring(int(a), int(c), ke, 0.1 * ke * 1e-3, 0.0)
        self.model = b.finalize(device="cpu")
        self.model.ground = False
        self.integrator = warp.sim.SemiImplicitIntegrator()
        self.s0, self.s1 = self.model.state(), self.model.state()
        self.dt = 0.2 * np.sqrt(mass / ke)
        self.springs, self.nodes = len(edges), len(pos)

    def frame(self, substeps: int) -> float:
        """ms per sub-step over ``substeps`` sub-steps."""
        t = time.perf_counter()
        for _ in range(substeps):
            self.s0.clear_forces()
            self.integrator.simulate(self.model, self.s0, self.s1, self.dt)
            self.s0, self.s1 = self.s1, self.s0
        self.wp.synchronize()
        return (time.perf_counter() - t) * 1e3 / substeps

    def finite(self) -> bool:
        return bool(np.isfinite(self.s0.particle_q.numpy()).all())


def run(ctx: Context) -> list[Row]:
    os.environ.setdefault("CUDA_VISIBLE_DEVICES", "")
    pos, edges = network()
    w = WarpSprings(pos, edges)
    w.frame(5)  # compiles the kernels (cached afterwards)
    scene = voxflex_scene(ctx)
    notes: dict = {}

    def voxflex() -> float:
        ms, n = voxflex_substep(ctx, scene)
        notes.update(n)
        return ms

    def peer() -> float:
        return float(np.median([w.frame(SUBSTEPS) for _ in range(5)]))

    times = interleave(ctx.repeat, [("voxflex", voxflex), ("peer", peer)])
    vn, vt = int(notes["proxy_nodes"]), int(notes["proxy_tetrahedra"])
    cells = CELLS[0] * CELLS[1] * CELLS[2]
    ok = (vn, vt) == (w.nodes, 5 * cells) and w.finite()
    import warp

    return [
        Row(
            job="springs",
            case=f"explicit sub-step, {vn:,} nodes, {w.springs:,} springs",
            peer=f"warp.sim {warp.__version__} SemiImplicitIntegrator, CPU",
            voxflex_ms=times["voxflex"],
            peer_ms=times["peer"],
            check=Check(
                ok=ok,
                what="voxflex proxy (nodes, tetrahedra) / Warp (nodes, 5 × cells; springs = their edges); Warp finite",
                value=f"({vn:,}, {vt:,}) / ({w.nodes:,}, {5 * cells:,}); finite {w.finite()}",
                tolerance="equal (work per sub-step; trajectories not compared)",
            ),
            note=(
                f"voxflex: model stage of `voxflex run` over its {int(notes['substeps'])} sub-steps "
                f"(per-frame work included); Warp: median of 5 frames of {SUBSTEPS} sub-steps"
            ),
        )
    ]
