//! Twin of `glsl/temporal/*.comp` (transient Gaussians), in f64: the same rows, the same floor,
//! cut-off and clamps. Rows `first..n` are transients; rows before them are left alone by the
//! forward (their opacity factor is 1) and get nothing from the backward.

use crate::kernels::deform::LOG_SCALE_MAX;
use crate::kernels::temporal::TemporalParams;

/// The temporal weight of one transient at time `t` (see `temporal_weight` in temporal.glsl).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weight {
    /// Opacity factor; 0 when below the cut-off (culled).
    pub w: f64,
    /// t − c.
    pub d: f64,
    /// 1 / σ².
    pub inv_s2: f64,
    /// τ ≤ the floor: σ is the floor and τ gets no gradient.
    pub floored: bool,
}

pub fn weight(c: f64, tau: f64, t: f64, p: &TemporalParams) -> Weight {
    let log_floor = p.log_floor as f64;
    let floored = tau.is_nan() || tau <= log_floor;
    let ls = if floored { log_floor } else { tau };
    let d = t - c;
    let inv_s2 = (-2.0 * ls).exp();
    let mut w = (-0.5 * d * d * inv_s2).exp();
    if w.is_nan() || w < p.cutoff as f64 {
        w = 0.0;
    }
    Weight {
        w,
        d,
        inv_s2,
        floored,
    }
}

/// The parameters of every row (the model's sections).
#[derive(Clone, Debug, Default)]
pub struct TemporalInputs {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub centre: Vec<f64>,
    pub log_width: Vec<f64>,
    pub velocity: Vec<[f64; 3]>,
}

/// What the forward writes for the transient rows (the canonical rows' drawn geometry is the
/// deformation's: `None` here) and the opacity factor of every row.
#[derive(Clone, Debug, Default)]
pub struct TemporalOut {
    pub means: Vec<Option<[f64; 3]>>,
    pub scales: Vec<Option<[f64; 3]>>,
    pub quats: Vec<Option<[f64; 4]>>,
    pub op_scale: Vec<f64>,
}

fn normalize(q: [f64; 4]) -> [f64; 4] {
    let l = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if l > 1e-12 {
        q.map(|v| v / l)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    }
}

/// Twin of `temporal_fwd` at time `p.t` over rows `0..p.n`.
pub fn forward(p: &TemporalParams, x: &TemporalInputs) -> TemporalOut {
    let n = p.n as usize;
    let mut o = TemporalOut {
        means: vec![None; n],
        scales: vec![None; n],
        quats: vec![None; n],
        op_scale: vec![1.0; n],
    };
    for i in (p.first as usize)..n {
        let r = weight(x.centre[i], x.log_width[i], p.t as f64, p);
        o.op_scale[i] = r.w;
        let d = if r.w > 0.0 { r.d } else { 0.0 };
        o.means[i] = Some(std::array::from_fn(|a| {
            x.means[i][a] + x.velocity[i][a] * d
        }));
        o.scales[i] = Some(x.log_scales[i].map(|l| l.min(LOG_SCALE_MAX as f64).exp()));
        o.quats[i] = Some(normalize(x.quats[i]));
    }
    o
}

/// Upstream gradients wrt what the forward produced (rows `0..n`; canonical rows ignored).
#[derive(Clone, Debug, Default)]
pub struct TemporalUpstream {
    pub means: Vec<[f64; 3]>,
    pub scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub op_scale: Vec<f64>,
}

/// Gradients of the transient rows' parameters (canonical rows: zeros, never written on the
/// GPU).
#[derive(Clone, Debug, Default)]
pub struct TemporalGrads {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub centre: Vec<f64>,
    pub log_width: Vec<f64>,
    pub velocity: Vec<[f64; 3]>,
}

/// Twin of `temporal_bwd`.
#[allow(clippy::needless_range_loop)] // one row's components across several arrays
pub fn backward(p: &TemporalParams, x: &TemporalInputs, up: &TemporalUpstream) -> TemporalGrads {
    let n = p.n as usize;
    let mut g = TemporalGrads {
        means: vec![[0.0; 3]; n],
        log_scales: vec![[0.0; 3]; n],
        quats: vec![[0.0; 4]; n],
        centre: vec![0.0; n],
        log_width: vec![0.0; n],
        velocity: vec![[0.0; 3]; n],
    };
    for i in (p.first as usize)..n {
        let r = weight(x.centre[i], x.log_width[i], p.t as f64, p);
        if r.w == 0.0 {
            continue;
        }
        let gm = up.means[i];
        let v = x.velocity[i];
        for a in 0..3 {
            g.means[i][a] = gm[a];
            let ls = x.log_scales[i][a];
            g.log_scales[i][a] = if ls <= LOG_SCALE_MAX as f64 {
                up.scales[i][a] * ls.exp()
            } else {
                0.0
            };
            g.velocity[i][a] = gm[a] * r.d;
        }
        let q = x.quats[i];
        let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if len > 1e-12 {
            let qn = q.map(|v| v / len);
            let dq = up.quats[i];
            let dot: f64 = (0..4).map(|a| qn[a] * dq[a]).sum();
            g.quats[i] = std::array::from_fn(|a| (dq[a] - qn[a] * dot) / len);
        }
        let k = up.op_scale[i] * r.w * r.inv_s2;
        let gv: f64 = (0..3).map(|a| gm[a] * v[a]).sum();
        g.centre[i] = k * r.d - gv;
        g.log_width[i] = if r.floored { 0.0 } else { k * r.d * r.d };
    }
    g
}

/// Twin of `temporal_disp`: δ of the transient rows, v·(t2 − t1) (canonical rows: `None`).
pub fn displacement(p: &TemporalParams, velocity: &[[f64; 3]]) -> Vec<Option<[f64; 3]>> {
    let dt = p.t2 as f64 - p.t as f64;
    (0..p.n as usize)
        .map(|i| (i >= p.first as usize).then(|| velocity[i].map(|v| v * dt)))
        .collect()
}

/// Twin of `temporal_disp_bwd`: what it adds to the velocity gradient of each row.
pub fn displacement_bwd(p: &TemporalParams, d_delta: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let dt = p.t2 as f64 - p.t as f64;
    (0..p.n as usize)
        .map(|i| {
            if i >= p.first as usize {
                d_delta[i].map(|g| g * dt)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Twin of `temporal_peak`: the logit densification prunes by.
pub fn peak(p: &TemporalParams, logits: &[f64], centre: &[f64], log_width: &[f64]) -> Vec<f64> {
    (0..p.n as usize)
        .map(|i| {
            let l = logits[i];
            if i < p.first as usize {
                return l;
            }
            let c = centre[i];
            let mut t = c.clamp(p.t_lo as f64, p.t_hi as f64);
            if t.is_nan() {
                t = p.t_lo as f64;
            }
            let r = weight(c, log_width[i], t, p);
            let q = r.w / (1.0 + (-l).exp());
            q.ln() - (1.0 - q).max(1e-30).ln()
        })
        .collect()
}
