// Prelude: volscatter-core medium::optics. `optical_depth` (midpoint quadrature through the
// medium's bounds, as on the CPU: same step positions and order) reads the including kernel's
// `params.bounds_lo`, `params.bounds_hi` and `params.density_scale`; needs density.wgsl and
// ray_box.wgsl. `ball_mean_inverse_square` is the ball kernel of a point emitter's 1/d^2.

// medium::optics::optical_depth: RGB optical depth from x along unit d over at most t_max, at
// most max_steps steps of at least min_step.
fn optical_depth(x: vec3<f32>, d: vec3<f32>, t_max: f32, min_step: f32, max_steps: u32) -> vec3<f32> {
    let span = ray_box(x, d, params.bounds_lo.xyz, params.bounds_hi.xyz);
    let t0 = span.x;
    let t1 = min(span.y, t_max);
    if (!(t0 < t1)) {
        return vec3<f32>(0.0);
    }
    let n = clamp(u32(ceil((t1 - t0) / min_step)), 1u, max_steps);
    let h = (t1 - t0) / f32(n);
    var tau = 0.0;
    for (var i = 0u; i < n; i++) {
        tau += density_at(x + d * (t0 + (f32(i) + 0.5) * h));
    }
    return params.density_scale.xyz * tau * h;
}

// medium::optics::ball_mean_inverse_square: the mean of 1/|y|^2 over a ball of radius r at distance d.
fn ball_mean_inverse_square(d: f32, r: f32) -> f32 {
    if (r <= 0.0) {
        return 1.0 / (d * d);
    }
    if (d < 1e-4 * r) {
        return 3.0 / (r * r);
    }
    let x = r / d;
    if (x < 0.25) {
        let x2 = x * x;
        return (1.0 + x2 * (0.2 + x2 * (3.0 / 35.0 + x2 / 21.0))) / (d * d);
    }
    let gap = max(abs(r - d), 1e-7 * r);
    return 1.5 / (r * r * r * d) * (0.5 * (r * r - d * d) * log((r + d) / gap) + d * r);
}

// medium::optics::lamp_inverse_square: a point lamp's 1/d^2, a sphere lamp's field (its interior
// dark, or lit at its surface's 2/r^2), spread over a ball of radius `near`.
fn lamp_inverse_square(d: f32, lamp: f32, near: f32, lit: bool) -> f32 {
    if (lamp <= near) {
        let ball = sqrt(lamp * lamp + near * near);
        let interior = select(0.0, 2.0 * lamp / (ball * ball * ball), lit && d < ball);
        return ball_mean_inverse_square(d, ball) + interior;
    }
    if (d < lamp) {
        return select(0.0, 2.0 / (lamp * lamp), lit);
    }
    let sin2 = min(lamp * lamp / (d * d), 1.0);
    var one_minus_cos = 1.0 - sqrt(1.0 - sin2);
    if (sin2 < 1e-3) {
        one_minus_cos = 0.5 * sin2 + 0.125 * sin2 * sin2;
    }
    return 2.0 * one_minus_cos / (lamp * lamp);
}
