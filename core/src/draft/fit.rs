//! Cubic Bézier splines fitted to polylines: fixed ends, handles along given
//! end tangents with least-squares lengths (chord-length parameters, six
//! Newton reparameterisations), split where the error is too large.

use glam::DVec3;

/// Newton reparameterisations of the points after the first fit.
const REPARAMETERISATIONS: usize = 6;

/// A cubic Bézier curve `[p0, p1, p2, p3]`.
pub type Cubic = [DVec3; 4];

pub fn eval(c: &Cubic, u: f64) -> DVec3 {
    let v = 1.0 - u;
    c[0] * (v * v * v) + c[1] * (3.0 * v * v * u) + c[2] * (3.0 * v * u * u) + c[3] * (u * u * u)
}

fn derivative(c: &Cubic, u: f64) -> DVec3 {
    let v = 1.0 - u;
    (c[1] - c[0]) * (3.0 * v * v) + (c[2] - c[1]) * (6.0 * v * u) + (c[3] - c[2]) * (3.0 * u * u)
}

fn second_derivative(c: &Cubic, u: f64) -> DVec3 {
    (c[2] - c[1] * 2.0 + c[0]) * (6.0 * (1.0 - u)) + (c[3] - c[2] * 2.0 + c[1]) * (6.0 * u)
}

/// Fits one cubic from `q[0]` to `q[q.len()-1]` leaving along `t0` and
/// arriving along `t1` (both unit, in the direction of travel). Returns the
/// curve, its largest distance to the points at their parameters and the
/// index of the point where that distance is reached.
pub fn fit_one(q: &[DVec3], t0: DVec3, t1: DVec3) -> (Cubic, f64, usize) {
    let (p0, p3) = (q[0], q[q.len() - 1]);
    let mut u = chord_parameters(q);
    let length: f64 = q.windows(2).map(|w| w[0].distance(w[1])).sum();
    let mut curve = handles(q, &u, p0, p3, t0, t1, length);
    for _ in 0..REPARAMETERISATIONS {
        for (k, uk) in u.iter_mut().enumerate().take(q.len() - 1).skip(1) {
            let d = eval(&curve, *uk) - q[k];
            let d1 = derivative(&curve, *uk);
            let denominator = d1.length_squared() + d.dot(second_derivative(&curve, *uk));
            if denominator > 0.0 {
                *uk = (*uk - d.dot(d1) / denominator).clamp(0.0, 1.0);
            }
        }
        curve = handles(q, &u, p0, p3, t0, t1, length);
    }
    let (mut error, mut worst) = (0.0, 0);
    for (k, (p, &uk)) in q.iter().zip(&u).enumerate() {
        let d = eval(&curve, uk).distance(*p);
        if d > error {
            (error, worst) = (d, k);
        }
    }
    (curve, error, worst)
}

fn chord_parameters(q: &[DVec3]) -> Vec<f64> {
    let mut u = Vec::with_capacity(q.len());
    let mut s = 0.0;
    u.push(0.0);
    for w in q.windows(2) {
        s += w[0].distance(w[1]);
        u.push(s);
    }
    if s > 0.0 {
        for x in &mut u {
            *x /= s;
        }
    }
    u
}

/// Handle lengths `a`, `b` minimising Σ |B(u_k) - q_k|² with
/// `p1 = p0 + a t0`, `p2 = p3 - b t1`; a third of the polyline's length
/// each when that system is singular or gives a handle outside
/// `(0.001, 1] × length`.
fn handles(q: &[DVec3], u: &[f64], p0: DVec3, p3: DVec3, t0: DVec3, t1: DVec3, length: f64) -> Cubic {
    let (mut c00, mut c01, mut c11, mut x0, mut x1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (p, &uk) in q.iter().zip(u) {
        let v = 1.0 - uk;
        let (b0, b1, b2, b3) = (v * v * v, 3.0 * v * v * uk, 3.0 * v * uk * uk, uk * uk * uk);
        let a0 = t0 * b1;
        let a1 = -t1 * b2;
        let r = *p - p0 * (b0 + b1) - p3 * (b2 + b3);
        c00 += a0.dot(a0);
        c01 += a0.dot(a1);
        c11 += a1.dot(a1);
        x0 += a0.dot(r);
        x1 += a1.dot(r);
    }
    let det = c00 * c11 - c01 * c01;
    let fallback = length / 3.0;
    let (mut a, mut b) = (fallback, fallback);
    if det.abs() > 1e-12 * (c00 * c11).max(f64::MIN_POSITIVE) {
        let (sa, sb) = ((x0 * c11 - x1 * c01) / det, (c00 * x1 - c01 * x0) / det);
        let ok = |h: f64| h > 1e-3 * length && h <= length;
        if ok(sa) && ok(sb) {
            (a, b) = (sa, sb);
        }
    }
    [p0, p0 + t0 * a, p3 - t1 * b, p3]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_cubic_it_was_sampled_from() {
        let c: Cubic = [DVec3::ZERO, DVec3::new(1.0, 1.0, 0.0), DVec3::new(2.0, 1.0, 0.5), DVec3::new(3.0, 0.0, 0.0)];
        let q: Vec<DVec3> = (0..=40).map(|k| eval(&c, k as f64 / 40.0)).collect();
        let (t0, t1) = ((c[1] - c[0]).normalize(), (c[3] - c[2]).normalize());
        let (fit, err, _) = fit_one(&q, t0, t1);
        assert!(err < 2e-3, "{err}");
        for k in 0..4 {
            assert!(fit[k].distance(c[k]) < 0.02, "{k}: {:?} vs {:?}", fit[k], c[k]);
        }
    }

    #[test]
    fn quarter_circle() {
        let q: Vec<DVec3> = (0..=32)
            .map(|k| {
                let a = std::f64::consts::FRAC_PI_2 * k as f64 / 32.0;
                DVec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let (fit, err, _) = fit_one(&q, DVec3::Y, -DVec3::X);
        // The best cubic quarter circle deviates by about 2.7e-4 of the radius.
        assert!(err < 1e-3, "{err}");
        assert!((fit[1].y - 0.55).abs() < 0.02, "{:?}", fit[1]);
    }
}
