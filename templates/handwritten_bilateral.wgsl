// The cross-bilateral filter of the `@bilateral` seed, written by hand the way
// a person would: sigma_s = 3 pixels, sigma_c = 0.5, no safety helpers. Used by
// `filterjit bench` to see how close generated code comes. Same bindings as a
// generated filter kernel without inputs.

struct Params {
    width: u32,
    height: u32,
    radius: u32,
    row_offset: u32,
}

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> buf_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> buf_out: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> buf_flags: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = i32(gid.x);
    let y = i32(gid.y + params.row_offset);
    let w = i32(params.width);
    let h = i32(params.height);
    if (x >= w || y >= h) {
        return;
    }
    let r = i32(params.radius);
    let i = y * w + x;
    let ci = buf_color[i].xyz;
    var sum_w = 0.0;
    var sum_c = vec3<f32>(0.0);
    for (var yj = max(y - r, 0); yj <= min(y + r, h - 1); yj++) {
        for (var xj = max(x - r, 0); xj <= min(x + r, w - 1); xj++) {
            let cj = buf_color[yj * w + xj].xyz;
            let dp = vec2<f32>(f32(xj - x), f32(yj - y));
            let dc = cj - ci;
            let weight = exp(-(dot(dp, dp) / 18.0 + dot(dc, dc) / 0.5));
            sum_w += weight;
            sum_c += weight * cj;
        }
    }
    buf_out[i] = vec4<f32>(sum_c / max(sum_w, 1e-30), 1.0);
    buf_flags[i] = 0u;
}
