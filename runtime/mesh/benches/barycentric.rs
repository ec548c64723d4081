//! Barycentric binding benchmark (`cargo bench -p voxflex-mesh --bench
//! barycentric`): every voxel of a 256³ volume (the sampling mesh's
//! vertices) bound to a uniform tetrahedral proxy of about 20 k
//! tetrahedra, then mapped (CPU path). Prints bind time, map time per frame
//! and the binding's memory. Pass a size to run smaller (`-- 128`).

use std::time::Instant;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_mesh::barycentric::BarycentricBinding;
use voxflex_mesh::proxy::uniform_proxy;

fn main() {
    let n: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(256);
    let grid = Grid::new([n; 3], DVec3::splat(0.8), DVec3::splat(-0.4 * n as f64));
    // Cells of n/16 voxels: 16³ cells, 20,480 tetrahedra.
    let mesh = uniform_proxy(&grid, (n / 16).max(1), |_| Some(0)).expect("proxy");
    println!(
        "voxflex-core barycentric bench: {n}³ points, {} tetrahedra, {} nodes, threads: {}",
        mesh.tets.len(),
        mesh.nodes.len(),
        rayon::current_num_threads()
    );
    let t = Instant::now();
    let b = BarycentricBinding::bind(&mesh, grid.len(), |i| {
        let (x, y, z) = (i % n, (i / n) % n, i / (n * n));
        grid.index_to_world(DVec3::new(x as f64, y as f64, z as f64))
    });
    println!(
        "bind: {:.0} ms ({} points outside), {} bytes per point",
        t.elapsed().as_secs_f64() * 1e3,
        b.outside,
        std::mem::size_of::<u32>() + std::mem::size_of::<[u16; 3]>()
    );
    let node_u: Vec<Vec<f32>> = (0..3)
        .map(|a| mesh.nodes.iter().map(|p| (p[a] * 0.01) as f32).collect())
        .collect();
    let mut out = [
        vec![0f32; grid.len()],
        vec![0f32; grid.len()],
        vec![0f32; grid.len()],
    ];
    let mut times = Vec::new();
    for _ in 0..5 {
        let [ox, oy, oz] = &mut out;
        let t = Instant::now();
        b.map(&mesh, [&node_u[0], &node_u[1], &node_u[2]], [ox, oy, oz]);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "map: {:.1} ms per frame (median of 5; min {:.1}, max {:.1})",
        times[2], times[0], times[4]
    );
}
