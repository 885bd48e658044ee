//! The track refinement's 6×6 least squares (point P and velocity v), solved in the directions
//! the rays pin and, in the ones they leave free, at the slowest velocity.
//!
//! Why not a ridge on v: the rays of a camera moving along a nearly straight path leave one
//! direction of (P, v) free (every track scaled about the path projects alike), and a ridge
//! strong enough to choose in it also shrinks the velocities the rays do pin (a 0.2 ridge took
//! a well-seen ball's speed from 3.5 to 2.7, `tests.rs`).

/// Eigenvalues under this share of the largest (after scaling v by the time offsets' RMS, so P
/// and v count alike) are directions the rays leave free.
pub const WEAK: f64 = 3e-3;

/// Minimises |A x − y|² given the normal equations `n` = AᵀA, `b` = Aᵀy, over x = (P, v); in
/// the directions where `n` is weaker than [`WEAK`] × its strongest, x is the one with the
/// smallest |v|. `s_rms`: the RMS of the rays' time offsets (the scale between P and v).
/// `None` when nothing is pinned or the input is not finite.
pub fn solve_slowest(n: [[f64; 6]; 6], b: [f64; 6], s_rms: f64) -> Option<[f64; 6]> {
    if s_rms.is_nan() || s_rms <= 0.0 || n.iter().flatten().chain(&b).any(|v| !v.is_finite()) {
        return None;
    }
    // Scaled unknowns z = D x, D = diag(1, 1, 1, s, s, s): n' = D⁻¹ n D⁻¹, b' = D⁻¹ b.
    let d = |i: usize| if i < 3 { 1.0 } else { s_rms };
    let ns: [[f64; 6]; 6] =
        std::array::from_fn(|i| std::array::from_fn(|j| n[i][j] / (d(i) * d(j))));
    let bs: [f64; 6] = std::array::from_fn(|i| b[i] / d(i));
    let (vals, vecs) = crate::linalg::jacobi(ns);
    let top = vals.iter().fold(0f64, |m, v| m.max(*v));
    if top.is_nan() || top <= 0.0 {
        return None;
    }
    let strong: Vec<usize> = (0..6).filter(|&k| vals[k] > WEAK * top).collect();
    let weak: Vec<usize> = (0..6).filter(|&k| vals[k] <= WEAK * top).collect();
    let col = |k: usize| -> [f64; 6] { std::array::from_fn(|i| vecs[i][k]) };
    let mut z = [0f64; 6];
    for &k in &strong {
        let u = col(k);
        let c = (0..6).map(|i| u[i] * bs[i]).sum::<f64>() / vals[k];
        for i in 0..6 {
            z[i] += c * u[i];
        }
    }
    // In the weak span, the c minimising |v(z + W c)|²: (WvᵀWv) c = −Wvᵀ v(z), small and
    // symmetric; a weak direction with no v part (a free P) stays at 0.
    let m = weak.len();
    if m > 0 {
        let wv = |a: usize, i: usize| col(weak[a])[3 + i];
        let mut g = vec![vec![0f64; m]; m];
        let mut r = vec![0f64; m];
        for (a, (ga, ra)) in g.iter_mut().zip(r.iter_mut()).enumerate() {
            for (c, gac) in ga.iter_mut().enumerate() {
                *gac = (0..3).map(|i| wv(a, i) * wv(c, i)).sum();
            }
            *ra = -(0..3).map(|i| wv(a, i) * z[3 + i]).sum::<f64>();
        }
        let c = solve_small(g, r);
        for a in 0..m {
            let u = col(weak[a]);
            for i in 0..6 {
                z[i] += c[a] * u[i];
            }
        }
    }
    let x: [f64; 6] = std::array::from_fn(|i| z[i] / d(i));
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// A small symmetric positive semi-definite system; a pivot near zero leaves its unknown at 0.
fn solve_small(mut g: Vec<Vec<f64>>, mut r: Vec<f64>) -> Vec<f64> {
    let m = r.len();
    let scale = g.iter().flatten().fold(0f64, |s, v| s.max(v.abs()));
    let mut x = vec![0f64; m];
    let mut live = vec![true; m];
    for c in 0..m {
        if g[c][c].abs() <= 1e-9 * scale.max(1e-300) {
            live[c] = false;
            continue;
        }
        for k in c + 1..m {
            let f = g[k][c] / g[c][c];
            let gc = g[c].clone();
            for (gkj, gcj) in g[k][c..].iter_mut().zip(&gc[c..]) {
                *gkj -= f * gcj;
            }
            r[k] -= f * r[c];
        }
    }
    for c in (0..m).rev() {
        if !live[c] {
            continue;
        }
        let s: f64 = (c + 1..m).map(|k| g[c][k] * x[k]).sum();
        x[c] = (r[c] - s) / g[c][c];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pinned_system_is_solved_exactly_and_a_free_direction_goes_slowest() {
        // Well posed: the solution of n x = b, whatever its speed.
        let n: [[f64; 6]; 6] = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                if i == j {
                    2.0
                } else {
                    0.1 * ((i + j) % 3) as f64
                }
            })
        });
        let x0 = [0.5, -1.0, 2.0, 3.0, -1.5, 1.0];
        let b: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| n[i][j] * x0[j]).sum());
        let x = solve_slowest(n, b, 1.0).expect("solved");
        for i in 0..6 {
            assert!((x[i] - x0[i]).abs() < 1e-9, "{x:?}");
        }
        // One free direction w = (1, 0, 0, 1, 0, 0)/√2 (P and v along x together): from any
        // solution, the slowest adds the multiple of w that zeroes v_x.
        let w = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0].map(|v: f64| v / 2f64.sqrt());
        let p: [[f64; 6]; 6] =
            std::array::from_fn(|i| std::array::from_fn(|j| (i == j) as u8 as f64 - w[i] * w[j]));
        let b: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| p[i][j] * x0[j]).sum());
        let x = solve_slowest(p, b, 1.0).expect("solved");
        assert!(x[3].abs() < 1e-9, "v_x {x:?}");
        // Still a solution: the projection of x − x0 off w is zero.
        let e: [f64; 6] = std::array::from_fn(|i| x[i] - x0[i]);
        let ew: f64 = (0..6).map(|i| e[i] * w[i]).sum();
        for i in 0..6 {
            assert!((e[i] - ew * w[i]).abs() < 1e-9, "{x:?}");
        }
        assert_eq!(solve_slowest([[0.0; 6]; 6], [0.0; 6], 1.0), None);
        assert_eq!(solve_slowest(n, [f64::NAN; 6], 1.0), None);
    }
}
