"""Job 6: one explicit mass-spring sub-step, voxflex against Warp's
``warp.sim`` ``SemiImplicitIntegrator`` on the CPU.

The network: the nodes of a 32 × 32 × 16-cell box at 2 mm (18,513 nodes),
springs on the edges of each cell's five-tetrahedra split (the twelve
cube edges and one diagonal per face: 104,528 springs), the face x = 0
fixed, gravity −9810 mm/s². voxflex's side is its own benchmark
(``cargo bench -p voxflex-mass-spring --bench mass_spring -- substep``,
volume springs off — springs only, like Warp's); Warp gets the same nodes
and edges built here with tests/reference/cantilever.py's split rule.

Same thing: the same network (node and spring counts equal) under the same
kind of integrator (symplectic Euler, damped springs, gravity). The spring
constants are derived differently (voxflex from E and ν, Warp given one
ke), which changes numbers but not work per sub-step, so the check is the
network's size and that Warp's state stays finite — not a trajectory.

Time: per sub-step, voxflex's median over 5 frames of many sub-steps as its
bench prints it; Warp's median over 5 frames of ``SUBSTEPS`` sub-steps.
"""

from __future__ import annotations

import os
import re
import subprocess
import time

import numpy as np

from common import Check, Context, HarnessError, Row, interleave

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


def voxflex_substep(ctx: Context) -> tuple[float, int, int]:
    """One run of voxflex's bench: (ms per sub-step, springs, nodes), volume springs off."""
    cmd = ["cargo", "bench", "-q", "-p", "voxflex-mass-spring", "--bench", "mass_spring", "--", "substep"]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ctx.repo, timeout=1800)
    if p.returncode != 0:
        raise HarnessError(f"{' '.join(cmd)} failed: {p.stderr.strip()[-1500:]}")
    pat = r"explicit sub-step, (\d+) springs, \d+ volume springs \(volume_stiffness = 0\), (\d+) nodes: ([\d.]+) ms"
    m = re.findall(pat, p.stdout)
    if not m:
        raise HarnessError(f"no springs-only sub-step line in:\n{p.stdout}")
    return float(m[0][2]), int(m[0][0]), int(m[0][1])


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
    counts = {}

    def voxflex() -> float:
        ms, springs, nodes = voxflex_substep(ctx)
        counts["voxflex"] = (springs, nodes)
        return ms

    def peer() -> float:
        return float(np.median([w.frame(SUBSTEPS) for _ in range(5)]))

    times = interleave(ctx.repeat, [("voxflex", voxflex), ("peer", peer)])
    vs, vn = counts["voxflex"]
    ok = (vs, vn) == (w.springs, w.nodes) and w.finite()
    import warp

    return [
        Row(
            job="springs",
            case=f"explicit sub-step, {vn:,} nodes, {vs:,} springs",
            peer=f"warp.sim {warp.__version__} SemiImplicitIntegrator, CPU",
            voxflex_ms=times["voxflex"],
            peer_ms=times["peer"],
            check=Check(
                ok=ok,
                what="network (springs, nodes) voxflex / Warp; Warp state finite",
                value=f"({vs:,}, {vn:,}) / ({w.springs:,}, {w.nodes:,}); finite {w.finite()}",
                tolerance="equal counts (work per sub-step; trajectories not compared)",
            ),
            note=f"voxflex: cargo bench, median of 5 frames; Warp: median of 5 frames of {SUBSTEPS} sub-steps",
        )
    ]
