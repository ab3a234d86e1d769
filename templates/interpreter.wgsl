// A stack interpreter for weight expressions: the design the thesis used on
// its GPU, kept only so `filterjit bench` can compare the JIT with it. Never
// used by filter or evolve. Same helpers (ops.wgsl is prepended), same filter.
//
// Program: one u32 per instruction, bits 0-7 opcode, 8-15 operator or
// variable slot, 16-31 argument (constant index, or feature slots i | j << 8).

struct Params {
    width: u32,
    height: u32,
    radius: u32,
    row_offset: u32,
    program_length: u32,
    pixels: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> buf_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> buf_out: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> buf_flags: array<u32>;
@group(0) @binding(4) var<storage, read> program: array<u32>;
@group(0) @binding(5) var<storage, read> constants: array<f32>;
@group(0) @binding(6) var<storage, read> features: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> variances: array<f32>;

const SLOT_PIXEL: u32 = 254u;
const SLOT_COLOR: u32 = 255u;
const STACK: u32 = 128u;

fn feature(slot: u32, index: u32, x: i32, y: i32) -> vec3<f32> {
    if (slot == SLOT_PIXEL) {
        return vec3<f32>(f32(x), f32(y), 0.0);
    }
    if (slot == SLOT_COLOR) {
        return buf_color[index].xyz;
    }
    return features[slot * params.pixels + index].xyz;
}

fn unary(op: u32, a: f32) -> f32 {
    switch op {
        case 0u: { return fj_neg(a); }
        case 1u: { return fj_sin(a); }
        case 2u: { return fj_cos(a); }
        case 3u: { return fj_tan(a); }
        case 4u: { return fj_exp(a); }
        case 5u: { return fj_asin(a); }
        case 6u: { return fj_acos(a); }
        case 7u: { return fj_atan(a); }
        case 8u: { return fj_sqrt(a); }
        case 9u: { return fj_abs(a); }
        case 10u: { return fj_mitchell(a); }
        case 11u: { return fj_sinc(a); }
        case 12u: { return fj_epanechnikov(a); }
        case 13u: { return fj_biweight(a); }
        default: { return fj_tricube(a); }
    }
}

fn binary(op: u32, a: f32, b: f32) -> f32 {
    switch op {
        case 0u: { return fj_add(a, b); }
        case 1u: { return fj_sub(a, b); }
        case 2u: { return fj_mul(a, b); }
        case 3u: { return fj_div(a, b); }
        default: { return fj_pow(a, b); }
    }
}

fn pair(op: u32, u: vec3<f32>, v: vec3<f32>) -> f32 {
    switch op {
        case 0u: { return fj_dot(u, v); }
        case 1u: { return fj_distance2(u, v); }
        case 2u: { return fj_distance1(u, v); }
        default: { return fj_distancemax(u, v); }
    }
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y + params.row_offset;
    if (x >= params.width || y >= params.height) {
        return;
    }
    let i = y * params.width + x;
    let r = i32(params.radius);
    let w = i32(params.width);
    let h = i32(params.height);
    var stack: array<f32, 128>;
    var sum_w: f32 = 0.0;
    var sum_c = vec3<f32>(0.0);
    for (var yj = max(i32(y) - r, 0); yj <= min(i32(y) + r, h - 1); yj++) {
        for (var xj = max(i32(x) - r, 0); xj <= min(i32(x) + r, w - 1); xj++) {
            let j = u32(yj * w + xj);
            var sp: u32 = 0u;
            for (var pc = 0u; pc < params.program_length; pc++) {
                let ins = program[pc];
                let op = ins & 0xffu;
                let sub = (ins >> 8u) & 0xffu;
                let arg = ins >> 16u;
                switch op {
                    case 0u: {
                        stack[sp] = constants[arg];
                        sp = sp + 1u;
                    }
                    case 1u: {
                        stack[sp] = variances[sub * params.pixels + i];
                        sp = sp + 1u;
                    }
                    case 2u: {
                        stack[sp - 1u] = unary(sub, stack[sp - 1u]);
                    }
                    case 3u: {
                        let b = stack[sp - 1u];
                        sp = sp - 1u;
                        stack[sp - 1u] = binary(sub, stack[sp - 1u], b);
                    }
                    default: {
                        let u = feature(arg & 0xffu, i, i32(x), i32(y));
                        let v = feature(arg >> 8u, j, xj, yj);
                        stack[sp] = pair(sub, u, v);
                        sp = sp + 1u;
                    }
                }
            }
            let w_ij = fj_weight(stack[0]);
            sum_w += w_ij;
            sum_c += w_ij * buf_color[j].xyz;
        }
    }
    let centre = buf_color[i];
    let filtered = vec4<f32>(sum_c / max(sum_w, FJ_TINY), centre.w);
    buf_out[i] = select(centre, filtered, sum_w > 0.0);
    buf_flags[i] = fj_domain;
}
