// The VPL gather (volscatter-core solvers/vpl/gather.rs `connect`): for each gather point, the
// light of the VPLs of its subset of walks, scattered towards the viewer: power x p(incident
// -> w) x p(w -> view) x T x G, G the clamp 1/max(d, R)^2 (with what the clamp lost against
// the ball kernel), the ball kernel, or the attenuated top hat. One workgroup per point, its 64 invocations taking
// every 64th VPL of this dispatch's range of the point's list, then a tree reduction; each
// dispatch adds its range into `out` (ranges are dispatched in turn so that a solve can be
// cancelled between them). The CPU sums the VPLs in list order, so the sums differ in their
// rounding only. affine, density_at, hg, PI, optical_depth and ball_mean_inverse_square come
// from the preludes (shaders/src/wgsl).

struct Params {
    density_w2i: array<vec4<f32>, 3>,
    density_brick_min: vec4<i32>,      // wgsl/density.wgsl
    density_brick_dims: vec4<u32>,
    density_scale: vec4<f32>,          // wgsl/optics.wgsl
    bounds_lo: vec4<f32>,
    bounds_hi: vec4<f32>,
    misc: vec4<f32>,                   // g, march step, -, -
    range: vec4<u32>,                  // first VPL of each list in this dispatch, VPLs per list, points, workgroups per row
};

struct Point {
    position: vec4<f32>,               // w = kernel radius (R of the clamp, or the ball's radius)
    view: vec4<f32>,                   // direction camera -> point, w = the ball radius the clamp's loss is measured against
    list: vec4<u32>,                   // first VPL of the point's list in `vpls`, its length, kernel (0 clamp, 1 ball, 2 hat), the phase-smoothing radius (f32 bits)
    hat: vec4<f32>,                    // kernel 2: the top hat's value inside its ball (RGB), -
};

struct Vpl {
    position: vec4<f32>,
    incident: vec4<f32>,
    power: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
@group(0) @binding(2) var<storage, read> points: array<Point>;
@group(0) @binding(3) var<storage, read> vpls: array<Vpl>;
// Three per point: (sum, connections shorter than the radius), (lost, -), (iso, -): iso the
// sum with the point's phase function replaced by 1 / 4 pi (vpl/energy.rs).
@group(0) @binding(4) var<storage, read_write> out: array<vec4<f32>>;

const WG: u32 = 64u;
var<workgroup> red_sum: array<vec4<f32>, 64>;
var<workgroup> red_lost: array<vec4<f32>, 64>;
var<workgroup> red_iso: array<vec4<f32>, 64>;

fn cone_mean_cosine(d: f32, r: f32) -> f32 {
    if (d <= r) {
        return 0.0;
    }
    let s = r / d;
    return 0.5 * (1.0 + sqrt(max(1.0 - s * s, 0.0)));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let pi = wg.x + params.range.w * wg.y;
    var sum = vec3<f32>(0.0);
    var lost = vec3<f32>(0.0);
    var iso = vec3<f32>(0.0);
    var near = 0.0;
    if (pi < params.range.z) {
        let p = points[pi];
        let x = p.position.xyz;
        let view = p.view.xyz;
        let radius = p.position.w;
        let ball = p.view.w;
        let g0 = params.misc.x;
        let cone = bitcast<f32>(p.list.w);
        let end = min(p.list.y, params.range.x + params.range.y);
        for (var v = params.range.x + lid; v < end; v += WG) {
            let vpl = vpls[p.list.x + v];
            let to = x - vpl.position.xyz;
            let d = length(to);
            if (d < radius) {
                near += 1.0;
            }
            let w = to / max(d, 1e-12);
            // Inside the top hat's ball: its constant, the phases' mean over the ball's
            // directions (HG with g^2), no transmittance (vpl/gather.rs `Kernel::Hat`).
            if (p.list.z == 2u && d < radius) {
                let pg = hg(-dot(vpl.incident.xyz, view), g0 * g0);
                sum += vpl.power.xyz * ((0.25 / PI) * pg) * p.hat.xyz;
                iso += vpl.power.xyz * ((0.25 / PI) * (0.25 / PI)) * p.hat.xyz;
                continue;
            }
            // The ball kernel's and the hat's phases smoothed over the cone of a ball of radius
            // `cone` (vpl/gather.rs `Kernel::Ball`, `cone_mean_cosine`).
            var g = g0;
            if (p.list.z >= 1u && cone > 0.0) {
                g = g0 * cone_mean_cosine(d, cone);
            }
            // At the VPL itself the direction is undefined: both lobes' mean, 1/4 pi.
            var p_vpl = 0.25 / PI;
            var p_view = 0.25 / PI;
            var tr = vec3<f32>(1.0);
            if (d > 1e-6) {
                p_vpl = hg(dot(vpl.incident.xyz, w), g);
                p_view = hg(-dot(w, view), g);
                tr = exp(-optical_depth(vpl.position.xyz, w, d, params.misc.y, 1024u));
            }
            let light = vpl.power.xyz * (p_vpl * p_view) * tr;
            let light_iso = vpl.power.xyz * (p_vpl * (0.25 / PI)) * tr;
            if (p.list.z == 1u) {
                let b = ball_mean_inverse_square(d, radius);
                sum += light * b;
                iso += light_iso * b;
            } else if (p.list.z == 2u) {
                let b = 1.0 / (d * d);
                sum += light * b;
                iso += light_iso * b;
            } else {
                let m = max(d, radius);
                let clamped = 1.0 / (m * m);
                sum += light * clamped;
                iso += light_iso * clamped;
                if (d < radius) {
                    lost += light * max(ball_mean_inverse_square(d, ball) - clamped, 0.0);
                }
            }
        }
    }
    red_sum[lid] = vec4<f32>(sum, near);
    red_lost[lid] = vec4<f32>(lost, 0.0);
    red_iso[lid] = vec4<f32>(iso, 0.0);
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s >>= 1u) {
        if (lid < s) {
            red_sum[lid] += red_sum[lid + s];
            red_lost[lid] += red_lost[lid + s];
            red_iso[lid] += red_iso[lid + s];
        }
        workgroupBarrier();
    }
    if (lid == 0u && pi < params.range.z) {
        out[3u * pi] += red_sum[0];
        out[3u * pi + 1u] += red_lost[0];
        out[3u * pi + 2u] += red_iso[0];
    }
}
