//! The layout hash: a fingerprint of every `#[repr(C)]` type that crosses the
//! boundary (type and field names, sizes, alignments, field offsets),
//! computed at compile time. Host and plugin compare it on load, so a plugin
//! built against a different layout is refused instead of corrupting memory.

use crate::ffi::*;
use std::mem::{align_of, offset_of, size_of};

/// 64-bit FNV-1a, usable in `const` context.
pub const fn fnv1a(mut hash: u64, bytes: &[u8]) -> u64 {
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

const fn mix(hash: u64, value: u64) -> u64 {
    fnv1a(hash, &value.to_le_bytes())
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

macro_rules! hash_type {
    ($h:ident, $ty:ident { $($field:ident),* $(,)? }) => {{
        $h = fnv1a($h, stringify!($ty).as_bytes());
        $h = mix($h, size_of::<$ty>() as u64);
        $h = mix($h, align_of::<$ty>() as u64);
        $( $h = fnv1a($h, stringify!($field).as_bytes()); $h = mix($h, offset_of!($ty, $field) as u64); )*
    }};
}

/// Computes the layout hash of every boundary type.
pub const fn compute() -> u64 {
    let mut h = FNV_OFFSET;
    hash_type!(h, StrRef { ptr, len });
    hash_type!(h, ErrorBuf { ptr, cap, len });
    hash_type!(
        h,
        PluginHeader {
            magic,
            abi_version,
            reserved,
            layout_hash,
            declaration
        }
    );
    hash_type!(
        h,
        PluginDeclaration {
            name,
            version,
            description,
            kind,
            capabilities,
            deformation,
            renderer,
            actuator,
            params_schema
        }
    );
    hash_type!(
        h,
        GridDesc {
            dims,
            spacing,
            origin
        }
    );
    hash_type!(
        h,
        VolumeDesc {
            grid,
            scalar_type,
            reserved,
            data,
            len
        }
    );
    hash_type!(
        h,
        RestPointsDesc {
            tag,
            reserved,
            grid,
            points,
            len
        }
    );
    hash_type!(
        h,
        FrameDesc {
            frame,
            frames,
            dt_s
        }
    );
    hash_type!(
        h,
        RegionDesc {
            tag,
            reserved,
            min,
            max
        }
    );
    hash_type!(
        h,
        DeformationVTable {
            create,
            destroy,
            init,
            bind,
            interact,
            step,
            dirty_region,
            map_cpu,
            map_gpu,
            removed_tetrahedra,
            notes,
            set_point_loads,
            compliance,
            resolve
        }
    );
    hash_type!(
        h,
        ActuatorGeometryDesc {
            points,
            len,
            triangles,
            triangle_count,
            gravity_m_s2
        }
    );
    hash_type!(
        h,
        ActuatorCommandDesc {
            tag,
            reserved,
            value
        }
    );
    hash_type!(
        h,
        ActuatorScalarsDesc {
            measure,
            effort_bounds,
            measure_bounds,
            has_loads,
            has_load_growth
        }
    );
    hash_type!(
        h,
        ActuatorVTable {
            create,
            destroy,
            init,
            command,
            linearise,
            notes
        }
    );
    hash_type!(
        h,
        GpuLimitsDesc {
            max_storage_buffer_binding_size,
            max_buffer_size,
            max_compute_workgroups_per_dimension,
            min_storage_buffer_offset_alignment
        }
    );
    hash_type!(
        h,
        BindingDesc {
            binding,
            reserved,
            buffer,
            offset,
            size
        }
    );
    hash_type!(
        h,
        HostApi {
            ctx,
            log,
            thread_count,
            gpu_available,
            gpu_adapter_description,
            gpu_limits,
            gpu_create_buffer,
            gpu_destroy_buffer,
            gpu_buffer_size,
            gpu_write_buffer,
            gpu_read_buffer,
            gpu_compile,
            gpu_dispatch,
            gpu_dispatch_indirect
        }
    );
    hash_type!(
        h,
        CameraDesc {
            target,
            azimuth_deg,
            elevation_deg,
            distance_mm,
            projection,
            width,
            projection_parameter,
            height,
            reserved
        }
    );
    hash_type!(
        h,
        RenderVolumeDesc {
            tag,
            reserved,
            volume,
            buffer,
            owner,
            release
        }
    );
    hash_type!(
        h,
        OpacityMapDesc {
            origin,
            dims,
            outside,
            reserved,
            values,
            len
        }
    );
    hash_type!(
        h,
        ImageTargetDesc {
            tag,
            reserved,
            pixels,
            len,
            buffer
        }
    );
    hash_type!(
        h,
        RenderStatsDesc {
            rays,
            samples,
            terminated_early
        }
    );
    hash_type!(
        h,
        RendererVTable {
            create,
            destroy,
            init,
            configure,
            set_volume,
            set_opacity_maps,
            render
        }
    );
    h = mix(h, size_of::<PluginKind>() as u64);
    h
}

#[cfg(test)]
mod tests {
    #[test]
    fn hash_is_stable_within_a_build_and_not_trivial() {
        assert_eq!(super::compute(), crate::LAYOUT_HASH);
        assert_ne!(crate::LAYOUT_HASH, 0);
        assert_ne!(
            super::fnv1a(super::FNV_OFFSET, b"a"),
            super::fnv1a(super::FNV_OFFSET, b"b")
        );
    }
}
