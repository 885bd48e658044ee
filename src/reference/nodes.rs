//! Twin of the control-node deformation field (`docs/nodes.md`): KNN of the canonical means
//! among the nodes, the per-Gaussian blend of the nodes' rigid transforms (linear blend
//! skinning) into a deformation row D = (dx 3, dr 4, ds 3), its backward (every path, weights
//! included) and the per-node gather of the contribution rows. Plain f64 loops, written from
//! the spec alone so that it cannot share a mistake with the kernels.

/// Fills the KNN slots that have no node (M < K, or a static Gaussian).
pub const NO_NODE: u32 = u32::MAX;
/// Log-radius clamp: keeps `exp(−2ρ)` finite both ways (no gradient to ρ outside).
pub const RHO_MIN: f64 = -16.0;
pub const RHO_MAX: f64 = 8.0;
/// Floats per (Gaussian, slot) contribution row: [dT(3), ddq(4), dds(3), dp(3), dρ(1)].
pub const CONTRIB: usize = 14;

/// Below this norm a quaternion normalises to the identity (as `deform_apply`).
const EPS: f64 = 1e-12;
const ID: [f64; 4] = [1.0, 0.0, 0.0, 0.0];

/// One valid KNN slot of a Gaussian: node position p, node log-radius rho, node MLP output row [T(3), dq(4), ds(3)].
#[derive(Clone, Copy, Debug)]
pub struct Slot {
    pub p: [f64; 3],
    pub rho: f64,
    pub out: [f64; 10],
}

fn dot<const D: usize>(a: [f64; D], b: [f64; D]) -> f64 {
    (0..D).map(|i| a[i] * b[i]).sum()
}

/// (q/|q|, |q|), or (identity, 0) when |q| ≤ EPS: the 0 tells the backward to stop there.
fn normalize(q: [f64; 4]) -> ([f64; 4], f64) {
    let len = dot(q, q).sqrt();
    if len > EPS {
        (q.map(|v| v / len), len)
    } else {
        (ID, 0.0)
    }
}

/// Gradient wrt q of `q/|q|` given the gradient wrt the unit quaternion (none when degenerate).
fn normalize_bwd(unit: [f64; 4], len: f64, g: [f64; 4]) -> [f64; 4] {
    if len > EPS {
        let d = dot(unit, g);
        [0, 1, 2, 3].map(|a| (g[a] - unit[a] * d) / len)
    } else {
        [0.0; 4]
    }
}

/// Hamilton product a ⊗ b, (w, x, y, z).
fn hamilton(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn conj(q: [f64; 4]) -> [f64; 4] {
    [q[0], -q[1], -q[2], -q[3]]
}

/// The 3DGS rotation matrix (a polynomial in q; exact identity at (1,0,0,0)).
fn rot(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    let (xx, yy, zz, xy, xz, yz) = (x * x, y * y, z * z, x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
}

/// ∂(u · R(q) v)/∂q of the polynomial R (the caller handles the normalisation).
fn rot_grad(u: [f64; 3], v: [f64; 3], q: [f64; 4]) -> [f64; 4] {
    let [w, x, y, z] = q;
    let dr = [
        [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]],
        [[0.0, y, z], [y, -2.0 * x, -w], [z, w, -2.0 * x]],
        [[-2.0 * y, x, w], [x, 0.0, z], [-w, z, -2.0 * y]],
        [[-2.0 * z, -w, x], [w, -2.0 * z, y], [x, y, 0.0]],
    ];
    dr.map(|m| 2.0 * (0..3).map(|i| u[i] * dot(m[i], v)).sum::<f64>())
}

/// Per-slot forward intermediates, shared by the forward and the backward: v = μ − p,
/// e = exp(−2ρ̃) = 1/σ², the softmax weight w (the log-weight a until the softmax),
/// r = (r̂, |r|) (|r| = 0 when degenerate), and disp = R(r̂) v − v + T, the slot's displacement of μ.
struct SlotFwd {
    v: [f64; 3],
    e: f64,
    w: f64,
    r: ([f64; 4], f64),
    disp: [f64; 3],
}

/// The slots' intermediates and Q.
fn blend(mu: [f64; 3], slots: &[Slot]) -> (Vec<SlotFwd>, [f64; 4]) {
    let mut f: Vec<SlotFwd> = slots
        .iter()
        .map(|s| {
            let e = (-2.0 * s.rho.clamp(RHO_MIN, RHO_MAX)).exp();
            let v = [0, 1, 2].map(|c| mu[c] - s.p[c]);
            let w = -dot(v, v) * e / 2.0;
            let r = normalize([0, 1, 2, 3].map(|c| ID[c] + s.out[3 + c]));
            let m = rot(r.0);
            let disp = [0, 1, 2].map(|c| dot(m[c], v) - v[c] + s.out[c]);
            SlotFwd { v, e, w, r, disp }
        })
        .collect();
    // Max-shifted softmax: the nearest slot gets exp(0) = 1, so the sum never underflows to 0.
    let amax = f.iter().map(|s| s.w).fold(f64::NEG_INFINITY, f64::max);
    f.iter_mut().for_each(|s| s.w = (s.w - amax).exp());
    let sum: f64 = f.iter().map(|s| s.w).sum();
    f.iter_mut().for_each(|s| s.w /= sum);
    // Q = Σ w r̂, the blended node rotation before normalisation.
    let mut q = [0.0; 4];
    for s in &f {
        for (qc, rc) in q.iter_mut().zip(s.r.0) {
            *qc += s.w * rc;
        }
    }
    (f, q)
}

/// K nearest nodes of every Gaussian (brute force): means [N][3], nodes [M][3] (f32, squared distance computed in f32 as dx*dx+dy*dy+dz*dz, in that order), nearest first, ties -> lower node index, NO_NODE fills slots when M < k. `active`: when Some, a Gaussian with active[i] == false gets all NO_NODE. Returns [N*k].
pub fn nodes_knn(
    means: &[[f32; 3]],
    nodes: &[[f32; 3]],
    k: usize,
    active: Option<&[bool]>,
) -> Vec<u32> {
    let mut out = vec![NO_NODE; means.len() * k];
    let mut best: Vec<(f32, u32)> = Vec::with_capacity(k + 1);
    for (i, m) in means.iter().enumerate() {
        if active.is_some_and(|act| !act[i]) {
            continue;
        }
        best.clear();
        for (j, n) in nodes.iter().enumerate() {
            let (dx, dy, dz) = (m[0] - n[0], m[1] - n[1], m[2] - n[2]);
            let d = dx * dx + dy * dy + dz * dz;
            // Strict `<`: an equal distance goes behind the lower index already there.
            let pos = best.iter().position(|b| d < b.0).unwrap_or(best.len());
            if pos < k {
                best.insert(pos, (d, j as u32));
                best.truncate(k);
            }
        }
        for (slot, &(_, j)) in out[i * k..(i + 1) * k].iter_mut().zip(&best) {
            *slot = j;
        }
    }
    out
}

/// Forward: the deformation row D = [dx(3), dr(4), ds(3)] of one Gaussian (canonical mean mu, raw quaternion q (w,x,y,z)) from its valid slots (empty -> all zeros).
pub fn nodes_lbs(mu: [f64; 3], q: [f64; 4], slots: &[Slot]) -> [f64; 10] {
    let mut d = [0.0; 10];
    if slots.is_empty() {
        return d;
    }
    let (f, big_q) = blend(mu, slots);
    for (s, sl) in f.iter().zip(slots) {
        for c in 0..3 {
            d[c] += s.w * s.disp[c];
            d[7 + c] += s.w * sl.out[7 + c];
        }
    }
    let (qb, _) = normalize(big_q);
    let (qh, _) = normalize(q);
    let r = hamilton(qb, qh);
    for c in 0..4 {
        d[3 + c] = r[c] - qh[c];
    }
    d
}

/// Backward: given g = dL/dD [10], returns (dL/dmu [3], dL/dq [4] (raw quaternion), per-slot contribution rows [dT(3), ddq(4), dds(3), dp(3), drho(1)]).
pub fn nodes_lbs_bwd(
    mu: [f64; 3],
    q: [f64; 4],
    slots: &[Slot],
    g: [f64; 10],
) -> ([f64; 3], [f64; 4], Vec<[f64; CONTRIB]>) {
    if slots.is_empty() {
        return ([0.0; 3], [0.0; 4], Vec::new());
    }
    let (gx, gr, gs) = (
        [g[0], g[1], g[2]],
        [g[3], g[4], g[5], g[6]],
        [g[7], g[8], g[9]],
    );
    let (f, big_q) = blend(mu, slots);
    let (qb, qlen_b) = normalize(big_q);
    let (qh, qlen) = normalize(q);
    // dr = q_b ⊗ q̂ − q̂: ∂/∂q_b = g ⊗ conj(q̂), ∂/∂q̂ = conj(q_b) ⊗ g − g.
    let g_qb = hamilton(gr, conj(qh));
    let cg = hamilton(conj(qb), gr);
    let g_qh = [0, 1, 2, 3].map(|c| cg[c] - gr[c]);
    let g_q = normalize_bwd(qh, qlen, g_qh);
    let g_big_q = normalize_bwd(qb, qlen_b, g_qb);

    // ∂L/∂w_k through dx, ds and Q; then the softmax backward.
    let gw: Vec<f64> = f
        .iter()
        .zip(slots)
        .map(|(s, sl)| {
            dot(gx, s.disp) + dot(gs, [sl.out[7], sl.out[8], sl.out[9]]) + dot(g_big_q, s.r.0)
        })
        .collect();
    let wgw: f64 = f.iter().zip(&gw).map(|(s, g)| s.w * g).sum();

    let mut g_mu = [0.0; 3];
    let mut rows = Vec::with_capacity(slots.len());
    for ((s, sl), gwk) in f.iter().zip(slots).zip(&gw) {
        let mut row = [0.0; CONTRIB];
        let w = s.w;
        let ga = w * (gwk - wgw);
        let m = rot(s.r.0);
        // Through dx = Σ w (R v − v + T) and a = −|v|² e / 2.
        let mut gv = [0.0; 3];
        for c in 0..3 {
            let rt_gx: f64 = (0..3).map(|i| m[i][c] * gx[i]).sum();
            gv[c] = w * (rt_gx - gx[c]) - ga * s.v[c] * s.e;
            g_mu[c] += gv[c];
            row[c] = w * gx[c];
            row[7 + c] = w * gs[c];
            row[10 + c] = -gv[c];
        }
        // Through R(r̂) v and Q = Σ w r̂, then r̂ = r/|r|.
        let gq_rot = rot_grad(gx, s.v, s.r.0);
        let g_rhat = [0, 1, 2, 3].map(|c| w * (gq_rot[c] + g_big_q[c]));
        row[3..7].copy_from_slice(&normalize_bwd(s.r.0, s.r.1, g_rhat));
        // ∂a/∂ρ̃ = |v|² e; nothing flows through the clamp from outside.
        if (RHO_MIN..=RHO_MAX).contains(&sl.rho) {
            row[13] = ga * dot(s.v, s.v) * s.e;
        }
        rows.push(row);
    }
    (g_mu, g_q, rows)
}

/// Per-node sums of the contribution rows: knn [N*k] (NO_NODE slots skipped), contrib [N*k][14] rows aligned with knn, m nodes. Returns (dL/d node_out [m][10], dL/d node params [m][4] = dp(3), drho(1)).
pub fn nodes_gather(
    knn: &[u32],
    contrib: &[[f64; CONTRIB]],
    m: usize,
) -> (Vec<[f64; 10]>, Vec<[f64; 4]>) {
    let mut g_out = vec![[0.0; 10]; m];
    let mut g_par = vec![[0.0; 4]; m];
    for (&j, row) in knn.iter().zip(contrib) {
        if j == NO_NODE {
            continue;
        }
        let j = j as usize;
        for c in 0..10 {
            g_out[j][c] += row[c];
        }
        for c in 0..4 {
            g_par[j][c] += row[10 + c];
        }
    }
    (g_out, g_par)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    type Case = ([f64; 3], [f64; 4], [f64; 10], Vec<Slot>);

    fn uni<const D: usize>(rng: &mut Pcg64, lo: f64, hi: f64) -> [f64; D] {
        [0; D].map(|_| rng.gen_range(lo..hi))
    }

    /// μ in the unit cube, a raw q, a functional u and K slots (p in the unit cube, ρ ≈ ln 0.5,
    /// ds ~ 0.1; T ~ 0.2 and dq ~ 0.3 when `moving`, else the identity transform).
    fn case(rng: &mut Pcg64, k: usize, moving: bool) -> Case {
        let (mu, q, u) = (uni(rng, 0.0, 1.0), uni(rng, -1.0, 1.0), uni(rng, -1.0, 1.0));
        let slots = (0..k)
            .map(|_| {
                let mut out = [0.0; 10];
                if moving {
                    out[..3].copy_from_slice(&uni::<3>(rng, -0.2, 0.2));
                    out[3..7].copy_from_slice(&uni::<4>(rng, -0.3, 0.3));
                }
                out[7..].copy_from_slice(&uni::<3>(rng, -0.1, 0.1));
                let (p, rho) = (uni(rng, 0.0, 1.0), 0.5f64.ln() + rng.gen_range(-0.3..0.3));
                Slot { p, rho, out }
            })
            .collect();
        (mu, q, u, slots)
    }

    /// L = u · D of the flat parameters [μ(3), q(4), per slot [T, dq, ds, p, ρ]] (the row layout).
    fn loss(x: &[f64], u: [f64; 10]) -> f64 {
        let slots: Vec<Slot> = x[7..]
            .chunks_exact(CONTRIB)
            .map(|r| {
                let (p, rho) = ([r[10], r[11], r[12]], r[13]);
                let out = r[..10].try_into().unwrap();
                Slot { p, rho, out }
            })
            .collect();
        let d = nodes_lbs([x[0], x[1], x[2]], [x[3], x[4], x[5], x[6]], &slots);
        dot(u, d)
    }

    /// Analytic gradient in the same flat layout.
    fn grad((mu, q, u, slots): &Case) -> Vec<f64> {
        let (gm, gq, rows) = nodes_lbs_bwd(*mu, *q, slots, *u);
        let mut g = [&gm[..], &gq].concat();
        g.extend(rows.iter().flatten());
        g
    }

    fn check_fd(c: &Case) {
        let (mu, q, u, slots) = c;
        let mut x: Vec<f64> = mu.iter().chain(q).copied().collect();
        for s in slots {
            x.extend(s.out.iter().chain(&s.p).chain([&s.rho]));
        }
        let an = grad(c);
        assert_eq!(an.len(), x.len());
        let h = 1e-6;
        for (i, &a) in an.iter().enumerate() {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += h;
            xm[i] -= h;
            let fd = (loss(&xp, *u) - loss(&xm, *u)) / (2.0 * h);
            let tol = 1e-6 * (1.0 + a.abs());
            assert!((fd - a).abs() <= tol, "#{i}: {fd} vs {a}");
        }
    }

    fn lbs(c: &Case) -> [f64; 10] {
        nodes_lbs(c.0, c.1, &c.3)
    }

    fn all_finite(c: &Case) -> bool {
        lbs(c).iter().chain(&grad(c)).all(|v| v.is_finite())
    }

    #[test]
    fn lbs_bwd_matches_finite_differences() {
        let mut rng = Pcg64::seed_from_u64(28);
        for k in [1, 2, 4] {
            for _ in 0..6 {
                check_fd(&case(&mut rng, k, true));
            }
        }
        // Identity node transforms: dx and dr exactly 0 (ds still blended), gradients still flow.
        let mut c = case(&mut rng, 3, false);
        let d = lbs(&c);
        assert!(d[..7].iter().all(|&v| v == 0.0), "{d:?}");
        assert!(d[7..].iter().all(|&v| v != 0.0), "{d:?}");
        check_fd(&c);
        // No slot: D = 0 and no gradient.
        c.3.clear();
        assert!(lbs(&c) == [0.0; 10] && grad(&c).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn far_gaussian_weights_sum_to_one() {
        let mut c = case(&mut Pcg64::seed_from_u64(7), 4, false);
        c.0 = [1000.0, -300.0, 500.0];
        let (t, ds) = ([0.1, -0.2, 0.05], [0.03, 0.0, -0.07]);
        for s in &mut c.3 {
            s.rho = 1e-3f64.ln();
            s.out[..3].copy_from_slice(&t);
            s.out[7..].copy_from_slice(&ds);
        }
        let (d, near) = (lbs(&c), |a: f64, b: f64| (a - b).abs() <= 1e-12);
        for a in 0..3 {
            assert!(near(d[a], t[a]) && near(d[7 + a], ds[a]), "{d:?}");
        }
        assert!(all_finite(&c));
        for (s, dq) in c.3.iter_mut().zip([0.3, -0.2, 0.1, 0.25]) {
            s.out[3..7].copy_from_slice(&[dq, -dq, 0.5 * dq, 0.1]);
        }
        assert!(all_finite(&c));
    }

    #[test]
    fn tiny_radius_clamp_and_coincident_nodes() {
        let mut c = case(&mut Pcg64::seed_from_u64(3), 3, false);
        c.0 = [0.5; 3];
        for (s, t) in c.3.iter_mut().zip([0.2, -0.1, 5.0]) {
            (s.p, s.rho) = ([0.2, 0.3, 0.4], -30.0);
            s.out[..3].copy_from_slice(&[t, 0.4 - t, 0.1]);
        }
        c.3[2].p = [0.9; 3];
        // The farther node's weight underflows to 0; the coincident pair splits the rest.
        let (d, o) = (lbs(&c), [c.3[0].out, c.3[1].out]);
        for a in [0, 1, 2, 7, 8, 9] {
            assert!((d[a] - (o[0][a] + o[1][a]) / 2.0).abs() <= 1e-12, "{d:?}");
        }
        assert!(all_finite(&c));
        // Clamped ρ: no gradient.
        assert!(grad(&c)[7..].chunks(CONTRIB).all(|r| r[13] == 0.0));
        // Rotating nodes at the low clamp (gradient flows there): still finite.
        for s in &mut c.3 {
            s.out[3..7].copy_from_slice(&[0.2, -0.3, 0.1, 0.05]);
            s.rho = RHO_MIN;
        }
        assert!(all_finite(&c));
        // The clamp acts on the value too: ρ beyond either end draws as the end itself.
        let mut c = case(&mut Pcg64::seed_from_u64(4), 3, true);
        for (lo, hi) in [(RHO_MIN, -30.0), (RHO_MAX, 9.0)] {
            c.3[0].rho = lo;
            let d = lbs(&c);
            c.3[0].rho = hi;
            assert_eq!(d, lbs(&c));
            assert_eq!(grad(&c)[7 + 13], 0.0);
        }
    }

    #[test]
    fn degenerate_quaternions_are_identity() {
        let mut c = case(&mut Pcg64::seed_from_u64(6), 2, true);
        // |r| = 0 draws as dq = 0 (r = identity), with no gradient to that slot's dq.
        c.3[0].out[3..7].copy_from_slice(&[0.0; 4]);
        let d = lbs(&c);
        c.3[0].out[3..7].copy_from_slice(&[-1.0, 0.0, 0.0, 0.0]);
        assert_eq!(d, lbs(&c));
        assert!(grad(&c)[7 + 3..7 + 7].iter().all(|&v| v == 0.0) && all_finite(&c));
        // A small |q| still normalises; |q| = 0 is the identity, with no gradient to q.
        let d = lbs(&c);
        c.1 = c.1.map(|v| v * 1e-3);
        assert!(lbs(&c).iter().zip(d).all(|(a, b)| (a - b).abs() <= 1e-12));
        c.1 = [0.0; 4];
        let d = lbs(&c);
        c.1 = [1.0, 0.0, 0.0, 0.0];
        assert_eq!(d, lbs(&c));
        c.1 = [0.0; 4];
        assert!(grad(&c)[3..7] == [0.0; 4] && all_finite(&c));
    }

    fn knn_oracle(m: &[[f32; 3]], n: &[[f32; 3]], k: usize, act: Option<&[bool]>) -> Vec<u32> {
        let mut out = Vec::new();
        for (i, a) in m.iter().enumerate() {
            let d2 = |b: &[f32; 3]| {
                let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
                x * x + y * y + z * z
            };
            let mut d: Vec<(f32, u32)> = n.iter().zip(0..).map(|(b, j)| (d2(b), j)).collect();
            d.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)));
            d.resize(k, (0.0, NO_NODE));
            let off = act.is_some_and(|a| !a[i]);
            out.extend(d.iter().map(|s| if off { NO_NODE } else { s.1 }));
        }
        out
    }

    #[test]
    fn knn_matches_sort_oracle() {
        let mut rng = Pcg64::seed_from_u64(11);
        for grid in [false, true] {
            // On a small integer grid many distances tie exactly.
            let mut pts = |n: usize| -> Vec<[f32; 3]> {
                let mut c = || [rng.gen::<f32>(), rng.gen_range(0..4) as f32][grid as usize];
                (0..n).map(|_| [c(), c(), c()]).collect()
            };
            let (means, nodes) = (pts(64), pts(37));
            let act: Vec<bool> = means.iter().map(|m| m[0] + m[1] < 1.5 * m[2]).collect();
            assert!(act.iter().any(|&a| a) && act.iter().any(|&a| !a));
            for k in [1, 4, 6] {
                for a in [None, Some(&act[..])] {
                    let want = knn_oracle(&means, &nodes, k, a);
                    assert_eq!(nodes_knn(&means, &nodes, k, a), want);
                }
            }
        }
        // Nodes 1 and 3 are equidistant: the lower index first.
        let (z, o) = (0.0, [[0.0f32; 3]]);
        let nodes = [[z, z, 3.0], [z, 1.0, z], [z, z, 0.5], [1.0, z, z]];
        assert_eq!(nodes_knn(&o, &nodes, 4, None), [2, 1, 3, 0]);
        let got = nodes_knn(&o, &nodes[..2], 4, None);
        assert_eq!(got, [1, 0, NO_NODE, NO_NODE]);
        let got = nodes_knn(&[o[0], o[0]], &nodes, 2, Some(&[false, true]));
        assert_eq!(got, [NO_NODE, NO_NODE, 2, 1]);
    }

    #[test]
    fn gather_matches_direct_loop() {
        let mut rng = Pcg64::seed_from_u64(5);
        let m = 5;
        // A fifth of the slots are NO_NODE; node m−1 is never drawn, its sums must stay 0.
        let knn: Vec<u32> = (0..7 * 3)
            .map(|_| rng.gen_range(0..m as u32).checked_sub(1).unwrap_or(NO_NODE))
            .collect();
        let contrib: Vec<[f64; CONTRIB]> = knn.iter().map(|_| uni(&mut rng, -1.0, 1.0)).collect();
        let (g_out, g_par) = nodes_gather(&knn, &contrib, m);
        assert_eq!((g_out.len(), g_par.len()), (m, m));
        for (j, (go, gp)) in g_out.iter().zip(&g_par).enumerate() {
            let mut want = [0.0; CONTRIB];
            for (_, row) in knn.iter().zip(&contrib).filter(|(&n, _)| n as usize == j) {
                want.iter_mut().zip(row).for_each(|(w, r)| *w += r);
            }
            for (g, w) in go.iter().chain(gp).zip(want) {
                assert!((g - w).abs() <= 1e-12, "node {j}");
            }
        }
        assert!(g_out[m - 1] == [0.0; 10] && g_par[m - 1] == [0.0; 4]);
        assert!(g_out.iter().flatten().any(|&v| v != 0.0));
    }
}
