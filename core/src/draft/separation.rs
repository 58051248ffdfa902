//! Separation checks on the surface: sections that nearly touch themselves
//! (`pinched`), and the final check that fitted splines meet only at shared
//! knots (`check_separation`).

use glam::DVec3;

use super::error::Failure;
use super::fit;
use super::limits::{MIN_CURVE_SEPARATION, NETWORK_NEIGHBOURHOOD};
use super::section::Polyline;
use super::surface::TriSurface;
use super::tracks::Source;

/// Whether section polylines come within `sep` of each other on one sheet
/// of the surface (see `TriSurface::same_sheet`) other than along
/// themselves: two polylines, or two parts of one polyline more than
/// `reach` apart along it (a plane through a saddle, a loop pinched where a
/// limb meets the body). Only points for which `keep` holds count.
pub(super) fn pinched(
    surface: &TriSurface,
    polys: &[&Polyline],
    sep: f64,
    reach: f64,
    keep: impl Fn(DVec3) -> bool,
) -> bool {
    // (polyline, arc length, position, triangle)
    let mut points: Vec<(usize, f64, DVec3, u32)> = Vec::new();
    let mut lengths = Vec::with_capacity(polys.len());
    for (pi, l) in polys.iter().enumerate() {
        let mut arc = 0.0;
        for i in 0..l.points.len() {
            if i > 0 {
                arc += l.points[i - 1].pos.distance(l.points[i].pos);
            }
            if keep(l.points[i].pos) {
                points.push((pi, arc, l.points[i].pos, l.tri_of_point(i)));
            }
        }
        lengths.push(l.length());
    }
    let apart = |a: &(usize, f64, DVec3, u32), b: &(usize, f64, DVec3, u32)| {
        if a.0 != b.0 {
            return f64::INFINITY;
        }
        let d = (a.1 - b.1).abs();
        if polys[a.0].closed { d.min(lengths[a.0] - d) } else { d }
    };
    first_close_pair(surface, &points, |x| (x.2, x.3), sep, |a, b| (apart(a, b) > reach).then_some(())).is_some()
}

/// The final check: splines sampled every quarter mean edge and projected
/// onto the surface come within [`MIN_CURVE_SEPARATION`] mean edges of each
/// other on one sheet of the surface (see `TriSurface::same_sheet`) only
/// where they are within [`NETWORK_NEIGHBOURHOOD`] mean edges of each other
/// along the curvenet: next to a shared knot, or where a curve turns around a
/// thin part. Anything else would be curves crossing (or nearly touching)
/// without a shared knot.
pub(super) fn check_separation(
    surface: &TriSurface,
    pool: &[[f64; 3]],
    splines: &[[u32; 4]],
    labels: &[Source],
) -> Result<(), Failure> {
    let edge = surface.mean_edge;
    let (delta, reach) = (MIN_CURVE_SEPARATION * edge, NETWORK_NEIGHBOURHOOD * edge);
    // Projected samples: (spline, arc length from the spline's start, point, triangle).
    let mut samples: Vec<(u32, f64, DVec3, u32)> = Vec::new();
    let mut lengths = Vec::with_capacity(splines.len());
    for (s, sp) in splines.iter().enumerate() {
        let c: fit::Cubic = sp.map(|i| DVec3::from_array(pool[i as usize]));
        let polygon = c[0].distance(c[1]) + c[1].distance(c[2]) + c[2].distance(c[3]);
        let n = ((polygon / (0.25 * edge)).ceil() as usize).clamp(8, 100_000);
        let mut arc = 0.0;
        let mut last: Option<DVec3> = None;
        for i in 0..=n {
            let q = fit::eval(&c, i as f64 / n as f64);
            if let Some(l) = last {
                arc += l.distance(q);
            }
            last = Some(q);
            let (p, t) = match surface.bvh.closest_point(q.to_array()) {
                Ok(h) => (DVec3::from_array(h.point), h.triangle),
                Err(_) => continue,
            };
            samples.push((s as u32, arc, p, t));
        }
        lengths.push(arc);
    }
    // Knot-to-knot distances along the network, up to `reach`.
    let n_knots = splines.iter().flat_map(|s| [s[0], s[3]]).max().map_or(0, |k| k as usize + 1);
    let mut adjacent: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n_knots];
    for (s, sp) in splines.iter().enumerate() {
        adjacent[sp[0] as usize].push((sp[3], lengths[s]));
        adjacent[sp[3] as usize].push((sp[0], lengths[s]));
    }
    let mut within: Vec<Option<Vec<(u32, f64)>>> = vec![None; n_knots];
    let mut knot_distance = |from: u32, to: u32| -> f64 {
        let reached = within[from as usize].get_or_insert_with(|| {
            // Dijkstra from `from`, stopping at `reach` (few knots are that close).
            let mut done: Vec<(u32, f64)> = Vec::new();
            let mut front: Vec<(u32, f64)> = vec![(from, 0.0)];
            while let Some(i) = (0..front.len()).min_by(|&a, &b| front[a].1.total_cmp(&front[b].1)) {
                let (k, d) = front.swap_remove(i);
                if done.iter().any(|x| x.0 == k) {
                    continue;
                }
                done.push((k, d));
                for &(m, len) in &adjacent[k as usize] {
                    if d + len <= reach && !done.iter().any(|x| x.0 == m) {
                        front.push((m, d + len));
                    }
                }
            }
            done
        });
        reached.iter().find(|x| x.0 == to).map_or(f64::INFINITY, |x| x.1)
    };
    let along =
        |a: &(u32, f64, DVec3, u32), b: &(u32, f64, DVec3, u32), knot_distance: &mut dyn FnMut(u32, u32) -> f64| {
            if a.0 == b.0 {
                return (a.1 - b.1).abs();
            }
            let (sa, sb) = (splines[a.0 as usize], splines[b.0 as usize]);
            let ends_a = [(sa[0], a.1), (sa[3], lengths[a.0 as usize] - a.1)];
            let ends_b = [(sb[0], b.1), (sb[3], lengths[b.0 as usize] - b.1)];
            let mut best = f64::INFINITY;
            for (ka, da) in ends_a {
                for (kb, db) in ends_b {
                    if da + db < reach && da + db < best {
                        best = best.min(da + db + knot_distance(ka, kb));
                    }
                }
            }
            best
        };
    let failure = first_close_pair(
        surface,
        &samples,
        |x| (x.2, x.3),
        delta,
        |a, b| {
            let net = along(a, b, &mut knot_distance);
            if net.is_nan() || net <= reach {
                return None;
            }
            let message = format!(
                "splines {} ({}) and {} ({}) come within {:.2} mean edges of each other on the surface near {:?}",
                a.0,
                labels[a.0 as usize],
                b.0,
                labels[b.0 as usize],
                a.2.distance(b.2) / edge,
                a.2.to_array()
            );
            let mut rings: Vec<usize> = [labels[a.0 as usize], labels[b.0 as usize]]
                .into_iter()
                .filter_map(|l| if let Source::Ring(k) = l { Some(k) } else { None })
                .collect();
            rings.dedup();
            Some(Failure { message, rings })
        },
    );
    failure.map_or(Ok(()), Err)
}

/// The first `found(a, b)` that is `Some`, over the pairs of `items` less
/// than `radius` apart on one sheet of the surface (see
/// `TriSurface::same_sheet`); `at` gives an item's position and triangle.
/// Each pair is visited once, `a` before `b` in `items`, found through a
/// uniform grid of cell `radius` (each item's own and 26 neighbouring
/// cells), in the same order every time.
fn first_close_pair<T, R>(
    surface: &TriSurface,
    items: &[T],
    at: impl Fn(&T) -> (DVec3, u32),
    radius: f64,
    mut found: impl FnMut(&T, &T) -> Option<R>,
) -> Option<R> {
    let cell = |p: DVec3| ((p / radius).floor()).as_i64vec3();
    let mut grid: rustc_hash::FxHashMap<glam::I64Vec3, Vec<u32>> = rustc_hash::FxHashMap::default();
    for (i, x) in items.iter().enumerate() {
        grid.entry(cell(at(x).0)).or_default().push(i as u32);
    }
    for (i, a) in items.iter().enumerate() {
        let (pa, ta) = at(a);
        let c = cell(pa);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = grid.get(&(c + glam::I64Vec3::new(dx, dy, dz))) else { continue };
                    for &j in list {
                        let b = &items[j as usize];
                        let (pb, tb) = at(b);
                        if (j as usize) <= i || pa.distance(pb) >= radius || !surface.same_sheet(ta, tb) {
                            continue;
                        }
                        if let Some(r) = found(a, b) {
                            return Some(r);
                        }
                    }
                }
            }
        }
    }
    None
}
