// Prelude: the Henyey-Greenstein phase function (volscatter-core phase::hg), for one
// anisotropy and per RGB channel, and the lobe helpers of POP's propagation kernels: clamp_a
// and cone_fraction mirror solvers/pop/propagate.rs (clamp_a) and phase::hg_cone_fraction.

const PI: f32 = 3.14159265358979;
const COS_45: f32 = 0.70710678118654752;

fn hg(c: f32, g: f32) -> f32 {
    let d = 1.0 + g * g - 2.0 * g * c;
    return (1.0 - g * g) / (4.0 * PI * d * sqrt(max(d, 1e-12)));
}

fn hg3(c: f32, g: vec3<f32>) -> vec3<f32> {
    let d = vec3<f32>(1.0) + g * g - 2.0 * g * c;
    return (vec3<f32>(1.0) - g * g) / (4.0 * PI * d * sqrt(max(d, vec3<f32>(1e-12))));
}

fn clamp_a(a: vec3<f32>) -> vec3<f32> {
    return clamp(a, vec3<f32>(-0.9995), vec3<f32>(0.9995));
}

// phase::hg_cone_fraction: HG energy in the cone cos >= c.
fn cone_fraction1(c: f32, g: f32) -> f32 {
    if (abs(g) < 1e-4) {
        return (1.0 - c) * 0.5;
    }
    let a = 1.0 + g * g;
    let f1 = 1.0 / sqrt(max(a - 2.0 * g, 1e-12));
    let fc = 1.0 / sqrt(max(a - 2.0 * g * c, 1e-12));
    return clamp((1.0 - g * g) / (2.0 * g) * (f1 - fc), 0.0, 1.0);
}

fn cone_fraction(c: f32, g: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(cone_fraction1(c, g.x), cone_fraction1(c, g.y), cone_fraction1(c, g.z));
}

// propagate.rs lobe_fractions: the fractions of a lobe of anisotropy a sent front, to each
// side and back (the 45-degree cones and the quarters of the band between them).
struct Lobe {
    front: vec3<f32>,
    side: vec3<f32>,
    back: vec3<f32>,
};

fn lobe_fractions(a: vec3<f32>) -> Lobe {
    var l: Lobe;
    let ca = clamp_a(a);
    l.front = cone_fraction(COS_45, ca);
    l.back = vec3<f32>(1.0) - cone_fraction(-COS_45, ca);
    l.side = max((vec3<f32>(1.0) - l.front - l.back) * 0.25, vec3<f32>(0.0));
    return l;
}

// propagate.rs path_factor (with the diffusion correction): kappa, the path one step stands
// for in cell lengths, from the transport coefficient sigma_tr and the drift front - back
// (`drift_matched`; else the ball's 1).
fn path_factor(a: vec3<f32>, lobe: Lobe, sigma_tr: vec3<f32>, h: f32, drift_matched: bool) -> vec3<f32> {
    let iso = min(sigma_tr * (0.5 * h), vec3<f32>(64.0));
    let aa = min(abs(a), vec3<f32>(1.0));
    var ball = vec3<f32>(1.0);
    if (drift_matched) {
        // Signed, as propagate.rs: a backward lobe (a < 0) drifts backwards along a positive path.
        let signed_a = select(min(a, vec3<f32>(-1e-3)), max(a, vec3<f32>(1e-3)), a >= vec3<f32>(0.0));
        ball = select(vec3<f32>(0.75), (lobe.front - lobe.back) / signed_a, aa > vec3<f32>(1e-3));
    }
    return aa * ball + (vec3<f32>(1.0) - aa) * iso;
}
