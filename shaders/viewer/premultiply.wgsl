// The viewer's 3D image from the session's GPU buffer into the texture egui
// draws: each u32 is an RGBA8 pixel (sRGB, straight alpha, R in the low
// byte), row by row from the top-left; egui's textures hold sRGB values
// with premultiplied alpha (Rgba8Unorm). The premultiplication rounds as
// egui's `Color32::from_rgba_unmultiplied` does, so this image equals the
// one the CPU path uploads.

@group(0) @binding(0) var<storage, read> pixels: array<u32>;
@group(0) @binding(1) var image: texture_storage_2d<rgba8unorm, write>;

// Workgroup edge, pixels.
const TILE: u32 = 8u;

// round(c · a / 255) for bytes c and a, in egui's fixed-point form.
fn premultiply(c: u32, a: u32) -> u32 {
    let p = c * a + 128u;
    return (p + (p >> 8u)) >> 8u;
}

@compute @workgroup_size(TILE, TILE, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(image);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let p = pixels[id.y * size.x + id.x];
    let a = p >> 24u;
    let rgba = vec4<u32>(
        premultiply(p & 255u, a),
        premultiply((p >> 8u) & 255u, a),
        premultiply((p >> 16u) & 255u, a),
        a,
    );
    textureStore(image, vec2<i32>(id.xy), vec4<f32>(rgba) / 255.0);
}
