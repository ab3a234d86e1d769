// filterjit's path tracer: next-event estimation, Russian roulette, box pixel
// filter, pinhole camera. One invocation renders `sample_count` samples of one
// pixel and writes their sums (and sums of squares) of colour and features;
// the host adds dispatches together in f64.
//
// Path depth follows Mitsuba's convention: max_depth counts path segments, so
// 1 sees emitters only and 2 is direct illumination.
//
// A frame of a sequence (with_motion) also writes each sample's motion
// vector as Blender's Vector pass does (docs/SCENES.md, "Sequences"): where
// its first hit was in the frame before (the hit point less its shape's step,
// seen through the frame before's camera; a miss, its direction) minus where
// it is, in pixels, x right and y up.

struct Prim {
    // x: kind (0 parallelogram, 1 sphere), y: material, z: emitter flag, w: unused
    info: vec4<u32>,
    // parallelogram: origin, area | sphere: centre, radius
    a: vec4<f32>,
    // parallelogram: edge u | sphere: unused
    u: vec4<f32>,
    // parallelogram: edge v | sphere: unused
    v: vec4<f32>,
    // parallelogram: unit normal | sphere: unused; w: 1/area of the emitter
    n: vec4<f32>,
    // emitted radiance (one-sided for parallelograms, outward for spheres)
    emission: vec4<f32>,
    // how far the shape moved since the frame before (a sequence's moving shape)
    step: vec4<f32>,
}

struct Material {
    // x: kind (0 diffuse, 1 glossy, 2 mirror, 3 glass), y: texture (0 constant, 1 checker, 2 stripes, 3 noise)
    info: vec4<u32>,
    // albedo; w: roughness (glossy) or index of refraction (glass)
    albedo: vec4<f32>,
    // second texture colour; w: texture frequency (cycles per world unit)
    albedo2: vec4<f32>,
}

struct Params {
    width: u32,
    height: u32,
    sample_offset: u32,
    sample_count: u32,
    seed: u32,
    with_features: u32,
    max_depth: u32,
    light_count: u32,
    prim_count: u32,
    row_offset: u32,
    // 1: write motion vectors against the frame before's camera (prev_*)
    with_motion: u32,
    _pad1: u32,
    environment: vec4<f32>,
    // camera: position; forward, right, up scaled by the half-extent of the image plane
    cam_pos: vec4<f32>,
    cam_forward: vec4<f32>,
    cam_right: vec4<f32>,
    cam_up: vec4<f32>,
    // the frame before's camera, likewise
    prev_pos: vec4<f32>,
    prev_forward: vec4<f32>,
    prev_right: vec4<f32>,
    prev_up: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> prims: array<Prim>;
@group(0) @binding(2) var<storage, read> materials: array<Material>;
@group(0) @binding(3) var<storage, read> lights: array<u32>;
@group(0) @binding(4) var<storage, read_write> sums: array<f32>;

// Floats per pixel in `sums`: colour, albedo, position, normal, secondary albedo
// (3 each), depth, visibility, motion x and y (1 each): 19 sums, then their squares.
const VALUES: u32 = 19u;
const STRIDE: u32 = 38u;
const PI: f32 = 3.14159265358979;
const INF: f32 = 1e30;
const EPS: f32 = 1e-4;

// ---- random numbers: PCG hash, one stream per (pixel, sample, seed) ----
var<private> rng_state: u32;

fn pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rand() -> f32 {
    rng_state = pcg(rng_state);
    return f32(rng_state >> 8u) * (1.0 / 16777216.0);
}

// ---- intersection ----
struct Hit {
    t: f32,
    prim: u32,
    p: vec3<f32>,
    n: vec3<f32>, // geometric normal as defined by the shape (not flipped)
}

fn intersect_prim(k: u32, o: vec3<f32>, d: vec3<f32>) -> f32 {
    let prim = prims[k];
    if (prim.info.x == 0u) {
        let n = prim.n.xyz;
        let denom = dot(n, d);
        if (abs(denom) < 1e-9) {
            return INF;
        }
        let t = dot(prim.a.xyz - o, n) / denom;
        if (t <= EPS) {
            return INF;
        }
        let q = o + t * d - prim.a.xyz;
        // Barycentric-style coordinates on the parallelogram.
        let uu = dot(prim.u.xyz, prim.u.xyz);
        let uv = dot(prim.u.xyz, prim.v.xyz);
        let vv = dot(prim.v.xyz, prim.v.xyz);
        let qu = dot(q, prim.u.xyz);
        let qv = dot(q, prim.v.xyz);
        let det = uu * vv - uv * uv;
        let s = (qu * vv - qv * uv) / det;
        let r = (qv * uu - qu * uv) / det;
        if (s < 0.0 || s > 1.0 || r < 0.0 || r > 1.0) {
            return INF;
        }
        return t;
    }
    let oc = o - prim.a.xyz;
    let b = dot(oc, d);
    let c = dot(oc, oc) - prim.a.w * prim.a.w;
    let disc = b * b - c;
    if (disc < 0.0) {
        return INF;
    }
    let sq = sqrt(disc);
    let t0 = -b - sq;
    if (t0 > EPS) {
        return t0;
    }
    let t1 = -b + sq;
    if (t1 > EPS) {
        return t1;
    }
    return INF;
}

fn intersect(o: vec3<f32>, d: vec3<f32>) -> Hit {
    var hit: Hit;
    hit.t = INF;
    hit.prim = 0xffffffffu;
    for (var k = 0u; k < params.prim_count; k++) {
        let t = intersect_prim(k, o, d);
        if (t < hit.t) {
            hit.t = t;
            hit.prim = k;
        }
    }
    if (hit.prim != 0xffffffffu) {
        hit.p = o + hit.t * d;
        let prim = prims[hit.prim];
        if (prim.info.x == 0u) {
            hit.n = prim.n.xyz;
        } else {
            hit.n = normalize(hit.p - prim.a.xyz);
        }
    }
    return hit;
}

fn occluded(o: vec3<f32>, target_point: vec3<f32>) -> bool {
    let to = target_point - o;
    let dist = length(to);
    let d = to / dist;
    for (var k = 0u; k < params.prim_count; k++) {
        let t = intersect_prim(k, o, d);
        if (t < dist * (1.0 - 1e-4)) {
            return true;
        }
    }
    return false;
}

// ---- textures (procedural, in world space) ----
fn hash3(p: vec3<i32>) -> f32 {
    let h = pcg(u32(p.x) * 73856093u ^ pcg(u32(p.y) * 19349663u ^ pcg(u32(p.z) * 83492791u)));
    return f32(h >> 8u) * (1.0 / 16777216.0);
}

fn value_noise(p: vec3<f32>) -> f32 {
    let i = vec3<i32>(floor(p));
    let f = fract(p);
    let w = f * f * (3.0 - 2.0 * f);
    let c000 = hash3(i);
    let c100 = hash3(i + vec3<i32>(1, 0, 0));
    let c010 = hash3(i + vec3<i32>(0, 1, 0));
    let c110 = hash3(i + vec3<i32>(1, 1, 0));
    let c001 = hash3(i + vec3<i32>(0, 0, 1));
    let c101 = hash3(i + vec3<i32>(1, 0, 1));
    let c011 = hash3(i + vec3<i32>(0, 1, 1));
    let c111 = hash3(i + vec3<i32>(1, 1, 1));
    let x00 = mix(c000, c100, w.x);
    let x10 = mix(c010, c110, w.x);
    let x01 = mix(c001, c101, w.x);
    let x11 = mix(c011, c111, w.x);
    return mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
}

fn albedo_at(m: Material, p: vec3<f32>) -> vec3<f32> {
    let f = m.albedo2.w;
    // A small offset keeps surfaces lying on integer planes off the pattern's seams.
    let q = p * f + vec3<f32>(1e-3, 2e-3, 3e-3);
    switch m.info.y {
        case 1u: {
            let c = vec3<i32>(floor(q));
            let odd = ((c.x + c.y + c.z) & 1) == 1;
            return select(m.albedo.xyz, m.albedo2.xyz, odd);
        }
        case 2u: {
            let odd = (i32(floor(q.x + q.z)) & 1) == 1;
            return select(m.albedo.xyz, m.albedo2.xyz, odd);
        }
        case 3u: {
            let t = 0.5 * value_noise(q) + 0.3 * value_noise(q * 2.7) + 0.2 * value_noise(q * 7.3);
            return mix(m.albedo.xyz, m.albedo2.xyz, clamp(t, 0.0, 1.0));
        }
        default: {
            return m.albedo.xyz;
        }
    }
}

// ---- BSDFs ----
fn onb(n: vec3<f32>) -> mat3x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bt = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return mat3x3<f32>(t, bt, n);
}

fn cosine_sample(n: vec3<f32>) -> vec3<f32> {
    let r1 = rand();
    let r2 = rand();
    let r = sqrt(r1);
    let phi = 2.0 * PI * r2;
    let local = vec3<f32>(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - r1)));
    return normalize(onb(n) * local);
}

fn ggx_d(nh: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let d = nh * nh * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

fn smith_g1(nv: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    return 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
}

fn fresnel_schlick(f0: vec3<f32>, c: f32) -> vec3<f32> {
    return f0 + (1.0 - f0) * pow(1.0 - clamp(c, 0.0, 1.0), 5.0);
}

// Glossy (GGX conductor tinted by the albedo): f(wi, wo) cos(wi).
fn glossy_eval(albedo: vec3<f32>, alpha: f32, n: vec3<f32>, wo: vec3<f32>, wi: vec3<f32>) -> vec3<f32> {
    let ni = dot(n, wi);
    let no = dot(n, wo);
    if (ni <= 0.0 || no <= 0.0) {
        return vec3<f32>(0.0);
    }
    let h = normalize(wi + wo);
    let d = ggx_d(max(dot(n, h), 0.0), alpha);
    let g = smith_g1(ni, alpha) * smith_g1(no, alpha);
    let f = fresnel_schlick(albedo, dot(wi, h));
    return f * d * g / (4.0 * no);
}

fn dielectric_fresnel(cos_i: f32, eta: f32) -> f32 {
    let sin2_t = eta * eta * max(0.0, 1.0 - cos_i * cos_i);
    if (sin2_t >= 1.0) {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

// ---- lights ----
struct LightSample {
    radiance: vec3<f32>, // Le * G * / pdf, without the BSDF
    wi: vec3<f32>,
    visible: bool,
}

// Sample a point on a uniformly chosen emitter as seen from `p`.
fn sample_light(p: vec3<f32>) -> LightSample {
    var out: LightSample;
    out.radiance = vec3<f32>(0.0);
    out.wi = vec3<f32>(0.0, 0.0, 1.0);
    out.visible = false;
    if (params.light_count == 0u) {
        return out;
    }
    let pick = min(u32(rand() * f32(params.light_count)), params.light_count - 1u);
    let prim = prims[lights[pick]];
    var x: vec3<f32>;
    var nl: vec3<f32>;
    let r1 = rand();
    let r2 = rand();
    if (prim.info.x == 0u) {
        x = prim.a.xyz + r1 * prim.u.xyz + r2 * prim.v.xyz;
        nl = prim.n.xyz;
    } else {
        let z = 1.0 - 2.0 * r1;
        let rr = sqrt(max(0.0, 1.0 - z * z));
        let phi = 2.0 * PI * r2;
        nl = vec3<f32>(rr * cos(phi), rr * sin(phi), z);
        x = prim.a.xyz + prim.a.w * nl;
    }
    let to = x - p;
    let dist2 = dot(to, to);
    let wi = to * inverseSqrt(dist2);
    out.wi = wi;
    let cos_l = dot(nl, -wi);
    out.visible = !occluded(p, x);
    if (cos_l <= 0.0 || !out.visible) {
        return out;
    }
    // pdf over area is n.w = 1/area; choosing the light is 1/light_count.
    out.radiance = prim.emission.xyz * cos_l / dist2 / (prim.n.w / f32(params.light_count));
    return out;
}

fn emitted(hit: Hit, d: vec3<f32>) -> vec3<f32> {
    let prim = prims[hit.prim];
    if (prim.info.z == 0u || dot(hit.n, -d) <= 0.0) {
        return vec3<f32>(0.0);
    }
    return prim.emission.xyz;
}

// ---- one path ----
struct Sample {
    color: vec3<f32>,
    albedo: vec3<f32>,
    position: vec3<f32>,
    normal: vec3<f32>,
    secondary: vec3<f32>,
    depth: f32,
    visibility: f32,
    // the first hit in the frame before (hit: whether there was one)
    previous: vec3<f32>,
    hit: bool,
}

fn surface_albedo(hit: Hit) -> vec3<f32> {
    let prim = prims[hit.prim];
    let m = materials[prim.info.y];
    if (m.info.x == 2u || m.info.x == 3u) {
        return vec3<f32>(1.0);
    }
    return albedo_at(m, hit.p);
}

fn trace(o_in: vec3<f32>, d_in: vec3<f32>) -> Sample {
    var s: Sample;
    s.color = vec3<f32>(0.0);
    s.albedo = vec3<f32>(0.0);
    s.position = vec3<f32>(0.0);
    s.normal = vec3<f32>(0.0);
    s.secondary = vec3<f32>(0.0);
    s.depth = 0.0;
    s.visibility = 0.0;
    var o = o_in;
    var d = d_in;
    var throughput = vec3<f32>(1.0);
    // Emission found by a BSDF-sampled ray counts only after a specular bounce
    // (or from the camera): otherwise next-event estimation already counted it.
    var count_emission = true;
    for (var segment = 1u; segment <= params.max_depth; segment++) {
        let hit = intersect(o, d);
        if (hit.prim == 0xffffffffu) {
            s.color += throughput * params.environment.xyz;
            break;
        }
        if (count_emission) {
            s.color += throughput * emitted(hit, d);
        }
        let prim = prims[hit.prim];
        let m = materials[prim.info.y];
        let front = dot(hit.n, d) < 0.0;
        let n = select(-hit.n, hit.n, front);
        let wo = -d;
        let p = hit.p + n * EPS;
        let albedo = select(albedo_at(m, hit.p), vec3<f32>(1.0), m.info.x >= 2u);

        if (segment == 1u && params.with_features != 0u) {
            s.albedo = albedo;
            s.position = hit.p;
            s.normal = hit.n;
            s.depth = hit.t;
            s.previous = hit.p - prim.step.xyz;
            s.hit = true;
            let r = reflect(d, n);
            let second = intersect(p, r);
            if (second.prim != 0xffffffffu) {
                s.secondary = surface_albedo(second);
            }
        }

        if (m.info.x == 0u || m.info.x == 1u) {
            // Next-event estimation, if a further segment is allowed.
            if (segment < params.max_depth) {
                let ls = sample_light(p);
                if (segment == 1u) {
                    s.visibility = select(0.0, 1.0, ls.visible);
                }
                var f = vec3<f32>(0.0);
                if (m.info.x == 0u) {
                    f = albedo / PI * max(dot(n, ls.wi), 0.0);
                } else {
                    f = glossy_eval(albedo, max(m.albedo.w, 0.02), n, wo, ls.wi);
                }
                s.color += throughput * f * ls.radiance;
            }
            count_emission = false;
            if (m.info.x == 0u) {
                d = cosine_sample(n);
                throughput *= albedo;
            } else {
                let alpha = max(m.albedo.w, 0.02);
                // Sample a microfacet normal from D(h) cos(h), reflect about it.
                let r1 = rand();
                let r2 = rand();
                let cos_h = sqrt((1.0 - r1) / (1.0 + (alpha * alpha - 1.0) * r1));
                let sin_h = sqrt(max(0.0, 1.0 - cos_h * cos_h));
                let phi = 2.0 * PI * r2;
                let h = normalize(onb(n) * vec3<f32>(sin_h * cos(phi), sin_h * sin(phi), cos_h));
                let wi = reflect(-wo, h);
                let pdf = ggx_d(cos_h, alpha) * cos_h / (4.0 * max(dot(wo, h), 1e-6));
                if (dot(wi, n) <= 0.0 || pdf <= 0.0) {
                    break;
                }
                throughput *= glossy_eval(albedo, alpha, n, wo, wi) / pdf;
                d = wi;
            }
            o = p;
        } else if (m.info.x == 2u) {
            d = reflect(d, n);
            throughput *= m.albedo.xyz;
            o = p;
            count_emission = true;
        } else {
            let eta = select(m.albedo.w, 1.0 / m.albedo.w, front);
            let cos_i = dot(n, wo);
            let fr = dielectric_fresnel(cos_i, eta);
            if (rand() < fr) {
                d = reflect(d, n);
                o = p;
            } else {
                d = refract(d, n, eta);
                o = hit.p - n * EPS;
                throughput *= m.albedo.xyz;
            }
            count_emission = true;
        }
        // Russian roulette after three segments.
        if (segment >= 3u) {
            let q = min(max(max(throughput.x, throughput.y), throughput.z), 0.95);
            if (rand() >= q) {
                break;
            }
            throughput /= q;
        }
    }
    return s;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y + params.row_offset;
    if (x >= params.width || y >= params.height) {
        return;
    }
    let pixel = y * params.width + x;
    var acc: array<f32, 38>;
    for (var k = 0u; k < STRIDE; k++) {
        acc[k] = 0.0;
    }
    for (var k = 0u; k < params.sample_count; k++) {
        let sample_index = params.sample_offset + k;
        rng_state = pcg(pcg(pixel ^ pcg(params.seed)) ^ sample_index * 2654435761u);
        let px = (f32(x) + rand()) / f32(params.width) * 2.0 - 1.0;
        let py = 1.0 - (f32(y) + rand()) / f32(params.height) * 2.0;
        let d = normalize(params.cam_forward.xyz + px * params.cam_right.xyz + py * params.cam_up.xyz);
        let s = trace(params.cam_pos.xyz, d);
        var motion = vec2<f32>(0.0);
        if (params.with_motion != 0u) {
            // Where the sample is on the image, and where its surface was in the frame before, in pixels.
            let here = vec2<f32>((px + 1.0) * 0.5 * f32(params.width), (1.0 - py) * 0.5 * f32(params.height));
            var toward = d;
            if (s.hit) {
                toward = s.previous - params.prev_pos.xyz;
            }
            let z = dot(toward, params.prev_forward.xyz);
            if (z > 0.0) {
                let qx = dot(toward, params.prev_right.xyz) / (dot(params.prev_right.xyz, params.prev_right.xyz) * z);
                let qy = dot(toward, params.prev_up.xyz) / (dot(params.prev_up.xyz, params.prev_up.xyz) * z);
                let there = vec2<f32>((qx + 1.0) * 0.5 * f32(params.width), (1.0 - qy) * 0.5 * f32(params.height));
                // Blender's convention: the frame before minus this one, y up.
                motion = vec2<f32>(there.x - here.x, here.y - there.y);
            } else {
                // Behind the camera before: far outside any image, no history.
                motion = vec2<f32>(1e7, 1e7);
            }
        }
        var values = array<f32, 19>(
            s.color.x, s.color.y, s.color.z,
            s.albedo.x, s.albedo.y, s.albedo.z,
            s.position.x, s.position.y, s.position.z,
            s.normal.x, s.normal.y, s.normal.z,
            s.secondary.x, s.secondary.y, s.secondary.z,
            s.depth, s.visibility, motion.x, motion.y,
        );
        for (var c = 0u; c < VALUES; c++) {
            acc[c] += values[c];
            acc[VALUES + c] += values[c] * values[c];
        }
    }
    // The sums hold the band's rows only: a whole large image's would pass
    // the device's largest storage binding (128 MiB on Mesa).
    let in_band = gid.y * params.width + x;
    for (var k = 0u; k < STRIDE; k++) {
        sums[in_band * STRIDE + k] = acc[k];
    }
}
