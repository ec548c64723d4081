//! Host-side cost of a dispatch: `cargo run --release -p voxflex-runtime
//! --example dispatch_cost` queues many small dispatches (three storage
//! bindings, one workgroup) and reports the wall time per dispatch, direct
//! and indirect, with one read-back at the end. Any adapter.

use std::time::Instant;
use voxflex_core::gpu::{BufferBinding, GpuService, GpuServiceExt};
use voxflex_runtime::gpu_context::{AdapterPolicy, WgpuService};

const KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> a: array<u32>;
@group(0) @binding(1) var<storage, read> b: array<u32>;
@group(0) @binding(2) var<storage, read_write> c: array<u32>;
@compute @workgroup_size(64)
fn add(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x < arrayLength(&c)) { c[gid.x] = c[gid.x] + a[gid.x] + b[gid.x]; }
}
"#;

fn main() {
    let gpu = WgpuService::new(AdapterPolicy::AnyAdapter).expect("a GPU adapter");
    println!("adapter: {}", gpu.adapter_description());
    let pipe = gpu.compile(KERNEL, "add").unwrap();
    let [a, b, c] = [1u32, 2, 0].map(|v| gpu.upload(&[v; 64], "buffer").unwrap());
    let args = gpu.upload(&[1u32, 1, 1], "args").unwrap();
    let bindings = [
        BufferBinding::whole(0, a),
        BufferBinding::whole(1, b),
        BufferBinding::whole(2, c),
    ];
    let mut out = [0u32; 64];
    for round in 0..3 {
        for indirect in [false, true] {
            let n = 5000;
            let t = Instant::now();
            for _ in 0..n {
                if indirect {
                    gpu.dispatch_indirect(pipe, &bindings, args, 0).unwrap();
                } else {
                    gpu.dispatch(pipe, &bindings, [1, 1, 1]).unwrap();
                }
            }
            let queued = t.elapsed();
            gpu.download(c, &mut out).unwrap();
            let total = t.elapsed();
            println!(
                "round {round}, {}: {:.1} µs per dispatch to queue, {:.1} µs with the run",
                if indirect { "indirect" } else { "direct" },
                queued.as_secs_f64() * 1e6 / n as f64,
                total.as_secs_f64() * 1e6 / n as f64
            );
        }
    }
}
