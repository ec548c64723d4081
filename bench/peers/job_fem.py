"""Job 5: the static cantilever, voxflex's corotational FEM against
scikit-fem (linear elasticity, scipy sparse direct solve) on the same mesh
with the same load.

Problem (tests/reference/cantilever.py): the 10 × 1 × 1 mm box, E = 1000,
ν = 0.3, clamped at x = 0, a uniform traction in −z on x = 10; the mesh has
nx = 10 r, ny = nz = r cells of five tetrahedra (50 r³ tetrahedra), nodes
on the voxel centres of voxflex's block proxy. voxflex's side is its
``fem_cantilever`` front (``voxflex bench --fronts --only fem_cantilever``:
a small load, static Newton, each proxy step × CG tolerance, P1 and P2);
the front's rows with integer r are the meshes scikit-fem solves here with
``cantilever.mesh(r)`` and the same element order.

Same thing: the tip deflection per unit load agrees to ``TIP_REL``
(relative). Per mesh and element the voxflex row used is the one with the
*loosest* CG tolerance that agrees — equal tip error, the cheapest voxflex
setting that reaches it. Time: voxflex's solve time from the front
(assembly, Newton, PCG); scikit-fem's basis + assembly + condensation +
direct solve (the mesh built before). Interleaving is per round: the whole
front, then every scikit-fem level.
"""

from __future__ import annotations

import csv
import importlib.util
import math

import numpy as np
import skfem
from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector, FacetBasis, LinearForm, asm, condense, solve
from skfem.models.elasticity import lame_parameters, linear_elasticity

from common import Check, Context, HarnessError, Row, run_voxflex, timed_ms

TIP_REL = 1e-3
EQUAL_ERROR = 0.01  # the "equal tip error" row: within 1 % of the finest answer
ELEMENTS = {"P1": ElementTetP1, "P2": ElementTetP2}


def reference_module(ctx: Context):
    """tests/reference/cantilever.py: its mesh rule and constants."""
    path = ctx.repo / "tests/reference/cantilever.py"
    spec = importlib.util.spec_from_file_location("cantilever_reference", path)
    if spec is None or spec.loader is None:
        raise HarnessError(f"cannot load {path}")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def skfem_tip(ref, mesh, element) -> float:
    """Tip deflection per unit load (mean −u_z over the tip's vertices)."""
    e = ElementVector(element())
    basis = Basis(mesh, e)
    K = asm(linear_elasticity(*lame_parameters(ref.E, ref.NU)), basis)
    tip = FacetBasis(mesh, e, facets=mesh.facets_satisfying(lambda x: np.isclose(x[0], ref.LENGTH)))

    @LinearForm
    def traction(v, w):
        return -ref.LOAD / (ref.WIDTH * ref.HEIGHT) * v.value[2]

    f = asm(traction, tip)
    clamped = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    u = solve(*condense(K, f, D=clamped))
    disp = u[basis.nodal_dofs].T
    at_tip = np.isclose(mesh.p[0], ref.LENGTH)
    return float(-disp[at_tip, 2].mean() / ref.LOAD)


def voxflex_front(ctx: Context, out_dir) -> list[dict]:
    args = ["bench", "--fronts", "--only", "fem_cantilever", "--out", out_dir]
    if ctx.quick:
        args.append("--quick")
    run_voxflex(ctx, *args)
    with open(out_dir / "fem_cantilever.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    out = []
    for r in rows:
        cells = float(r["cells_per_mm"])
        if abs(cells - round(cells)) > 1e-9:
            continue  # not one of cantilever.py's meshes
        out.append(
            {
                "element": r["series"].split()[0],
                "r": int(round(cells)),
                "tol": float(r["cg_tolerance"]),
                "tip": float(r["tip_u_per_p"]),
                "ms": float(r["time_ms"]),
                "tets": int(r["tetrahedra"]),
            }
        )
    if not out:
        raise HarnessError("the fem_cantilever front gave no row on an integer mesh")
    return out


def run(ctx: Context) -> list[Row]:
    ref = reference_module(ctx)
    out_dir = ctx.case_dir("fem")
    pairs = sorted({(r["element"], r["r"]) for r in voxflex_front(ctx, out_dir)})
    meshes = {r: ref.mesh(r) for _, r in pairs}
    vox: dict[tuple, list[list[dict]]] = {p: [] for p in pairs}
    peer: dict[tuple, list[float]] = {p: [] for p in pairs}
    tips: dict[tuple, float] = {}
    for el, r in pairs:  # warm-up of the peer, and its answer
        tips[(el, r)] = skfem_tip(ref, meshes[r], ELEMENTS[el])
    for _ in range(ctx.repeat):
        front = voxflex_front(ctx, out_dir)
        for p in pairs:
            vox[p].append([x for x in front if (x["element"], x["r"]) == p])
        for el, r in pairs:
            ms, _ = timed_ms(lambda r=r, el=el: skfem_tip(ref, meshes[r], ELEMENTS[el]))
            peer[(el, r)].append(ms)
    rows = []
    for p in pairs:
        el, r = p
        # Per tolerance: the tip (deterministic up to CG) and the times of every round.
        by_tol: dict[float, list[dict]] = {}
        for round_rows in vox[p]:
            for x in round_rows:
                by_tol.setdefault(x["tol"], []).append(x)
        agree = [
            t for t in sorted(by_tol, reverse=True) if abs(by_tol[t][0]["tip"] - tips[p]) <= TIP_REL * abs(tips[p])
        ]
        tol = agree[0] if agree else min(by_tol)
        chosen = by_tol[tol]
        rel = abs(chosen[0]["tip"] - tips[p]) / abs(tips[p])
        beam = 4.0  # P L³ / (3 E I): Euler–Bernoulli, for the error column
        rows.append(
            Row(
                job="fem",
                case=f"cantilever {el}, r = {r} ({chosen[0]['tets']:,} tetrahedra)",
                peer=f"scikit-fem {skfem.__version__} {el}, scipy direct",
                voxflex_ms=[x["ms"] for x in chosen],
                peer_ms=peer[p],
                check=Check(
                    ok=bool(agree),
                    what="tip u/P, voxflex / scikit-fem",
                    value=f"{chosen[0]['tip']:.6f} / {tips[p]:.6f} (rel. {rel:.1e})",
                    tolerance=f"rel. ≤ {TIP_REL:g}",
                ),
                note=f"voxflex CG tol. {tol:g}; tip vs Euler–Bernoulli (4.0) {abs(tips[p] - beam) / beam:.1%}",
                extra={"tip_voxflex": chosen[0]["tip"], "tip_peer": tips[p], "cg_tolerance": tol},
            )
        )
    if any(math.isnan(t) for t in tips.values()):
        raise HarnessError("scikit-fem gave a NaN tip")
    rows.append(equal_error_row(vox, peer, tips))
    return rows


def equal_error_row(vox: dict, peer: dict, tips: dict) -> Row:
    """The issue's goal: each side's cheapest setting (element, mesh, and
    for voxflex CG tolerance) whose tip is within ``EQUAL_ERROR`` of the
    finest answer here (scikit-fem, the highest order on the finest mesh)."""
    finest = tips[max(tips, key=lambda p: (p[0], p[1]))]
    close = lambda tip: abs(tip - finest) <= EQUAL_ERROR * abs(finest)  # noqa: E731
    vox_cands = []  # (median ms, label, times)
    for p, rounds in vox.items():
        by_tol: dict[float, list[dict]] = {}
        for rr in rounds:
            for x in rr:
                by_tol.setdefault(x["tol"], []).append(x)
        for tol, xs in by_tol.items():
            if close(xs[0]["tip"]):
                times = [x["ms"] for x in xs]
                vox_cands.append((sorted(times)[len(times) // 2], f"{p[0]} r = {p[1]}, CG {tol:g}", times))
    peer_cands = [(sorted(t)[len(t) // 2], f"{p[0]} r = {p[1]}", t) for p, t in peer.items() if close(tips[p])]
    ok = bool(vox_cands and peer_cands)
    v = min(vox_cands) if vox_cands else (None, "none", [])
    q = min(peer_cands) if peer_cands else (None, "none", [])
    return Row(
        job="fem",
        case=f"cantilever, cheapest setting within {EQUAL_ERROR:.0%} of the finest tip",
        peer=f"scikit-fem {skfem.__version__}, cheapest element and mesh",
        voxflex_ms=v[2],
        peer_ms=q[2],
        check=Check(
            ok=ok,
            what="both reach the error",
            value=f"voxflex {v[1]}; scikit-fem {q[1]} (finest tip {finest:.6f})",
            tolerance=f"tip within {EQUAL_ERROR:.0%}",
        ),
        note="equal tip error, each side's cheapest setting among those measured",
    )
