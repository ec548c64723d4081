"""Independent linear-elasticity reference for the cantilever accuracy test
of the corotational FEM plugin (issue #5).

Solves small-strain isotropic linear elasticity with P1 tetrahedra on the
*same* meshes the Rust test builds, with scikit-fem and a direct sparse
solve, and writes `cantilever.json` beside this script.

Run from the repository root:
    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install -r tests/reference/requirements.txt
    /tmp/venv/bin/python tests/reference/cantilever.py

Problem: the box [0, 10] x [0, 1] x [0, 1]; E = 1000, nu = 0.3; every node
with x = 0 clamped; a uniform traction of 1 in -z on the face x = 10 (total
force 1), as consistent P1 nodal loads (each boundary triangle of area A
gives A/3 to each of its corners). Beam theory: P L^3 / (3 E I) = 4.

Mesh rule (mirrored by the Rust test): nx = 10 r, ny = nz = r cells; node
(i, j, k) at (10 i / nx, j / ny, k / nz) with index i + (nx+1)(j + (ny+1) k);
cell (ci, cj, ck) of parity (ci + cj + ck) & 1 split into five tetrahedra
by its corners c = cx + 2 cy + 4 cz:
    parity 0: [0,1,2,4] [1,2,3,7] [1,4,5,7] [2,4,6,7] [1,2,4,7]
    parity 1: [0,1,3,5] [0,2,3,6] [0,4,5,6] [3,5,6,7] [0,3,5,6]
"""

import json
import pathlib

import numpy as np
import scipy
import skfem
from skfem import Basis, ElementTetP1, ElementVector, FacetBasis, LinearForm, MeshTet, asm, condense, solve
from skfem.models.elasticity import lame_parameters, linear_elasticity

E, NU = 1000.0, 0.3
LENGTH, WIDTH, HEIGHT, LOAD = 10.0, 1.0, 1.0, 1.0
CELL_TETS = [
    [[0, 1, 2, 4], [1, 2, 3, 7], [1, 4, 5, 7], [2, 4, 6, 7], [1, 2, 4, 7]],
    [[0, 1, 3, 5], [0, 2, 3, 6], [0, 4, 5, 6], [3, 5, 6, 7], [0, 3, 5, 6]],
]


def mesh(r):
    nx, ny, nz = 10 * r, r, r
    i, j, k = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    # Node index i + (nx+1)(j + (ny+1) k): x fastest.
    order = lambda a: a.transpose(2, 1, 0).ravel()
    p = np.vstack([order(i) * LENGTH / nx, order(j) * WIDTH / ny, order(k) * HEIGHT / nz])
    node = lambda a, b, c: a + (nx + 1) * (b + (ny + 1) * c)
    tets = []
    for ck in range(nz):
        for cj in range(ny):
            for ci in range(nx):
                for corners in CELL_TETS[(ci + cj + ck) & 1]:
                    tets.append([node(ci + (c & 1), cj + ((c >> 1) & 1), ck + (c >> 2)) for c in corners])
    t = np.array(tets).T
    # Orient positively (scikit-fem expects it); swapping two corners of a
    # tetrahedron does not change the P1 space.
    x = p[:, t]
    vol = np.einsum("ij,ij->j", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0], axis=0))
    t[[1, 2]] = np.where(vol < 0, t[[2, 1]], t[[1, 2]])
    check_conforming(p, t)
    return MeshTet(p, np.ascontiguousarray(t))


def check_conforming(p, t):
    """The mirrored pattern must make neighbouring cells cut their shared
    square face along the same diagonal. Then every triangle is a face of one
    tetrahedron (boundary) or two (interior), and the boundary triangles tile
    exactly the surface of the box; a mismatched diagonal would leave
    unpaired triangles inside and overshoot the surface area."""
    faces = np.sort(t.T[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    unique, count = np.unique(faces, axis=0, return_counts=True)
    assert count.max() <= 2, "no triangle is shared by three tetrahedra"
    b = unique[count == 1]
    x = p[:, b]  # (coordinate, triangle, corner)
    area = 0.5 * np.linalg.norm(np.cross(x[:, :, 1] - x[:, :, 0], x[:, :, 2] - x[:, :, 0], axis=0), axis=0).sum()
    surface = 2 * (LENGTH * WIDTH + LENGTH * HEIGHT + WIDTH * HEIGHT)
    assert abs(area - surface) < 1e-9, "boundary triangles tile the box surface: the mesh is conforming"


def solve_level(r):
    m = mesh(r)
    e = ElementVector(ElementTetP1())
    basis = Basis(m, e)
    assert abs(basis.dx.sum() - LENGTH * WIDTH * HEIGHT) < 1e-9, "the mesh fills the box"
    K = asm(linear_elasticity(*lame_parameters(E, NU)), basis)
    tip = FacetBasis(m, e, facets=m.facets_satisfying(lambda x: np.isclose(x[0], LENGTH)))

    @LinearForm
    def traction(v, w):
        return -LOAD / (WIDTH * HEIGHT) * v.value[2]

    f = asm(traction, tip)
    assert abs(f.sum() + LOAD) < 1e-12, "the load totals 1"
    clamped = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    u = solve(*condense(K, f, D=clamped))
    disp = u[basis.nodal_dofs].T  # (nodes, 3), node order of the mesh rule
    at_tip = np.isclose(m.p[0], LENGTH)
    level = {
        "r": r,
        "nodes": int(m.p.shape[1]),
        "tets": int(m.t.shape[1]),
        "tip_uz_mean": float(disp[at_tip, 2].mean()),
        "tip_uz_min": float(disp[at_tip, 2].min()),
        "tip_ux_mean": float(disp[at_tip, 0].mean()),
    }
    if r <= 2:
        level["displacements"] = [[float(v) for v in row] for row in disp]
    return level


def main():
    levels = [solve_level(r) for r in (1, 2, 3, 4, 6, 8)]
    out = {
        "problem": {
            "youngs_modulus": E,
            "poisson_ratio": NU,
            "length": LENGTH,
            "width": WIDTH,
            "height": HEIGHT,
            "load": LOAD,
            "direction": "-z",
            "beam_theory_tip_deflection": LOAD * LENGTH**3 / (3 * E * WIDTH * HEIGHT**3 / 12),
            "mesh": "nx=10r, ny=nz=r cells, nodes x-fastest, five tetrahedra per cell by parity (see cantilever.py)",
        },
        "levels": levels,
        "generated_by": f"scikit-fem {skfem.__version__}, numpy {np.__version__}, scipy {scipy.__version__}",
    }
    path = pathlib.Path(__file__).with_name("cantilever.json")
    path.write_text(json.dumps(out, indent=1) + "\n")
    for lv in levels:
        print(f"r={lv['r']}: {lv['nodes']} nodes, {lv['tets']} tets, tip u_z {lv['tip_uz_mean']:.6f}")


if __name__ == "__main__":
    main()
