//! The deformation network of Deformable-3DGS (`DeformNetwork`), as configuration plus a layout
//! of every Linear into ONE flat f32 parameter buffer shared by the GPU kernels, the CPU twin
//! (`reference::mlp`) and Adam.
//!
//! Network (DESIGN §2): `h0 = [γ(x), t_feat]`, `in_dims = 63 + t_feat_dims` for `x_freqs = 10`;
//! trunk layer `i` is `h = ReLU(W_i h + b_i)`; after the ReLU of layer `skip`,
//! `h = [γ(x), t_feat, h]`, so layer `skip + 1` takes `width + in_dims` inputs; the head is one
//! Linear(width, 10) without activation: `out[0..3] = dx`, `out[3..7] = dr`, `out[7..10] = ds`.
//! `t_feat = γ(t)` (Direct) or `timenet(γ(t))` with timenet = Linear(13, 256)–ReLU–Linear(256, 30)
//! (TimeNet). γ(v) = [v, sin(2^0 v), cos(2^0 v), …, sin(2^(L−1) v), cos(2^(L−1) v)].

use rand::{Rng, SeedableRng};

use crate::error::{Error, Result};

/// Parameter offsets are aligned to this many floats (256 bytes: any storage-buffer binding
/// offset alignment, and whole cache lines).
pub const PARAM_ALIGN: usize = 64;

/// Outputs of the head: dx (3), dr (4), ds (3).
pub const OUT_DIMS: usize = 10;

/// How time enters the network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeEncoding {
    /// `t_feat = γ(t)` with `freqs` frequencies (real captures: 10 → 21 dims).
    Direct { freqs: u32 },
    /// `t_feat = Linear(hidden, out)(ReLU(Linear(1 + 2·freqs, hidden)(γ(t))))` (synthetic scenes:
    /// freqs 6, hidden 256, out 30).
    TimeNet { freqs: u32, hidden: u32, out: u32 },
}

/// Depth, width, skip and encodings: the speed/accuracy knob, all runtime values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MlpConfig {
    /// Trunk ReLU layers (Deformable-3DGS: 8).
    pub depth: u32,
    /// Trunk width (256).
    pub width: u32,
    /// Index of the trunk layer after whose ReLU the encoded input is concatenated again
    /// (`Some(depth / 2)`); must be below `depth − 1`.
    pub skip: Option<u32>,
    /// Frequencies of γ(x) (10 → 63 dims).
    pub x_freqs: u32,
    pub time: TimeEncoding,
}

impl MlpConfig {
    /// Real captures (NeRF-DS, HyperNeRF): 8×256, skip 4, γ(x) L=10, γ(t) L=10.
    pub fn real() -> Self {
        MlpConfig {
            depth: 8,
            width: 256,
            skip: Some(4),
            x_freqs: 10,
            time: TimeEncoding::Direct { freqs: 10 },
        }
    }

    /// Synthetic/blender scenes: 8×256, skip 4, γ(x) L=10, γ(t) L=6 through the time net.
    pub fn synthetic() -> Self {
        MlpConfig {
            time: TimeEncoding::TimeNet {
                freqs: 6,
                hidden: 256,
                out: 30,
            },
            ..Self::real()
        }
    }

    /// γ(x) dims: 3 + 6·x_freqs.
    pub fn x_dims(&self) -> usize {
        3 + 6 * self.x_freqs as usize
    }

    /// γ(t) dims: 1 + 2·freqs.
    pub fn t_enc_dims(&self) -> usize {
        match self.time {
            TimeEncoding::Direct { freqs } | TimeEncoding::TimeNet { freqs, .. } => {
                1 + 2 * freqs as usize
            }
        }
    }

    pub fn t_freqs(&self) -> u32 {
        match self.time {
            TimeEncoding::Direct { freqs } | TimeEncoding::TimeNet { freqs, .. } => freqs,
        }
    }

    /// Time features entering the trunk: γ(t) (Direct) or the time net's output.
    pub fn t_feat_dims(&self) -> usize {
        match self.time {
            TimeEncoding::Direct { .. } => self.t_enc_dims(),
            TimeEncoding::TimeNet { out, .. } => out as usize,
        }
    }

    /// Trunk input dims: `x_dims + t_feat_dims` (real 84, synthetic 93).
    pub fn in_dims(&self) -> usize {
        self.x_dims() + self.t_feat_dims()
    }

    pub fn time_net(&self) -> bool {
        matches!(self.time, TimeEncoding::TimeNet { .. })
    }

    /// Checks the configuration; every error names the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(format!("MlpConfig: {m}")));
        if self.depth == 0 || self.depth > 64 {
            return bad(format!("depth = {}: expected 1..=64", self.depth));
        }
        if self.width == 0 || self.width > 4096 {
            return bad(format!("width = {}: expected 1..=4096", self.width));
        }
        if let Some(s) = self.skip {
            if s + 1 >= self.depth {
                return bad(format!(
                    "skip = {s}: expected below depth − 1 = {} (the concatenation feeds a trunk layer)",
                    self.depth - 1
                ));
            }
        }
        if self.x_freqs > 24 || self.t_freqs() > 24 {
            return bad("x_freqs/time freqs: expected at most 24".into());
        }
        if let TimeEncoding::TimeNet { hidden, out, .. } = self.time {
            if hidden == 0 || out == 0 || hidden > 4096 || out > 4096 {
                return bad(format!(
                    "time net hidden = {hidden}, out = {out}: expected 1..=4096"
                ));
            }
        }
        Ok(())
    }

    /// Multiply-adds per Gaussian of one forward pass (backward ≈ 2× that).
    pub fn macs_per_gaussian(&self) -> u64 {
        MlpLayout::new(self)
            .map(|l| {
                l.linears
                    .iter()
                    .map(|s| (s.fan_in * s.fan_out) as u64)
                    .sum()
            })
            .unwrap_or(0)
    }
}

/// Which part of the network a Linear belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinearRole {
    TimeNet(u32),
    Trunk(u32),
    Head,
}

/// One Linear: weights row-major `[fan_out][fan_in]` (as PyTorch) at `w_off`, bias at `b_off`,
/// both in floats into the flat parameter buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinearSpec {
    pub role: LinearRole,
    pub fan_in: usize,
    pub fan_out: usize,
    pub w_off: usize,
    pub b_off: usize,
}

/// Every Linear's place in the flat parameter buffer: time net L0, L1 (when present), trunk
/// layers 0..depth, head; each weight and bias offset aligned to [`PARAM_ALIGN`] floats.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MlpLayout {
    pub cfg: MlpConfig,
    /// In evaluation order.
    pub linears: Vec<LinearSpec>,
    /// Floats in the parameter buffer (a multiple of PARAM_ALIGN).
    pub total: usize,
}

impl MlpLayout {
    pub fn new(cfg: &MlpConfig) -> Result<Self> {
        cfg.validate()?;
        let mut linears = Vec::new();
        let mut off = 0usize;
        let mut push = |role, fan_in: usize, fan_out: usize| {
            let w_off = off;
            off = (off + fan_in * fan_out).next_multiple_of(PARAM_ALIGN);
            let b_off = off;
            off = (off + fan_out).next_multiple_of(PARAM_ALIGN);
            linears.push(LinearSpec {
                role,
                fan_in,
                fan_out,
                w_off,
                b_off,
            });
        };
        if let TimeEncoding::TimeNet { hidden, out, .. } = cfg.time {
            push(LinearRole::TimeNet(0), cfg.t_enc_dims(), hidden as usize);
            push(LinearRole::TimeNet(1), hidden as usize, out as usize);
        }
        let w = cfg.width as usize;
        for i in 0..cfg.depth {
            let fan_in = if i == 0 {
                cfg.in_dims()
            } else if cfg.skip.map(|s| s + 1) == Some(i) {
                w + cfg.in_dims()
            } else {
                w
            };
            push(LinearRole::Trunk(i), fan_in, w);
        }
        push(LinearRole::Head, w, OUT_DIMS);
        Ok(MlpLayout {
            cfg: *cfg,
            linears,
            total: off,
        })
    }

    pub fn time_net(&self) -> &[LinearSpec] {
        let n = if self.cfg.time_net() { 2 } else { 0 };
        &self.linears[..n]
    }

    pub fn trunk(&self) -> &[LinearSpec] {
        let n = if self.cfg.time_net() { 2 } else { 0 };
        &self.linears[n..self.linears.len() - 1]
    }

    pub fn head(&self) -> &LinearSpec {
        self.linears.last().unwrap()
    }

    /// Float ranges of the parameter groups (for per-group learning rates): time net (empty
    /// without one), trunk, head.
    pub fn groups(&self) -> [std::ops::Range<usize>; 3] {
        let tn_end = self.trunk()[0].w_off;
        let head = self.head().w_off;
        [0..tn_end, tn_end..head, head..self.total]
    }

    /// Parameters as PyTorch's default `nn.Linear` init draws them: W and b uniform in
    /// `[−1/√fan_in, 1/√fan_in)`, from a PCG stream seeded by `seed` (reproducible). Padding
    /// between tensors is zero.
    pub fn init_params(&self, seed: u64) -> Vec<f32> {
        self.init_params_gain(seed, 1.0)
    }

    /// [`Self::init_params`] with every weight bound (not the biases') scaled by `gain`:
    /// `gain = √6` is He's uniform init for ReLU layers, which keeps the activations' scale
    /// through the trunk where PyTorch's default shrinks it ≈ 2.4× per layer.
    pub fn init_params_gain(&self, seed: u64, gain: f32) -> Vec<f32> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let mut p = vec![0.0f32; self.total];
        for l in &self.linears {
            let bound = 1.0 / (l.fan_in as f32).sqrt();
            for v in &mut p[l.w_off..l.w_off + l.fan_in * l.fan_out] {
                *v = gain * rng.gen_range(-bound..bound);
            }
            for v in &mut p[l.b_off..l.b_off + l.fan_out] {
                *v = rng.gen_range(-bound..bound);
            }
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_have_deformable_3dgs_shapes() {
        let r = MlpLayout::new(&MlpConfig::real()).unwrap();
        assert_eq!(r.cfg.in_dims(), 84);
        assert_eq!(r.linears.len(), 9);
        assert_eq!(r.trunk()[0].fan_in, 84);
        assert_eq!(r.trunk()[5].fan_in, 256 + 84);
        assert_eq!(r.trunk()[4].fan_in, 256);
        assert_eq!((r.head().fan_in, r.head().fan_out), (256, 10));
        let s = MlpLayout::new(&MlpConfig::synthetic()).unwrap();
        assert_eq!(s.cfg.in_dims(), 93);
        assert_eq!(s.time_net()[0].fan_in, 13);
        assert_eq!((s.time_net()[1].fan_in, s.time_net()[1].fan_out), (256, 30));
        assert_eq!(s.trunk()[5].fan_in, 256 + 93);
        for l in &s.linears {
            assert_eq!(l.w_off % PARAM_ALIGN, 0);
            assert_eq!(l.b_off % PARAM_ALIGN, 0);
            assert!(l.b_off >= l.w_off + l.fan_in * l.fan_out);
        }
        assert!(s.total >= s.head().b_off + 10);
        let [tn, trunk, head] = s.groups();
        assert_eq!(
            (tn.start, trunk.start, head.end),
            (0, s.trunk()[0].w_off, s.total)
        );
        assert!(r.groups()[0].is_empty());
    }

    #[test]
    fn bad_skip_is_named() {
        let c = MlpConfig {
            skip: Some(7),
            ..MlpConfig::real()
        };
        let e = MlpLayout::new(&c).unwrap_err().to_string();
        assert!(e.contains("skip = 7"), "{e}");
    }

    #[test]
    fn init_matches_pytorch_linear_moments_and_is_seeded() {
        let l = MlpLayout::new(&MlpConfig::synthetic()).unwrap();
        let p = l.init_params(7);
        assert_eq!(p, l.init_params(7), "same seed, same parameters");
        assert_ne!(p, l.init_params(8));
        for s in &l.linears {
            let b = 1.0 / (s.fan_in as f64).sqrt();
            let w: Vec<f64> = p[s.w_off..s.w_off + s.fan_in * s.fan_out]
                .iter()
                .map(|&v| v as f64)
                .collect();
            let n = w.len() as f64;
            let mean = w.iter().sum::<f64>() / n;
            let var = w.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
            // U(−b, b): mean 0, variance b²/3; standard errors b/√(3n) and ≈ 0.30·b²/√n.
            assert!(
                mean.abs() < 5.0 * b / (3.0 * n).sqrt(),
                "{s:?}: mean {mean}"
            );
            let want = b * b / 3.0;
            assert!(
                (var - want).abs() < 5.0 * 0.3 * b * b / n.sqrt(),
                "{s:?}: var {var} vs {want}"
            );
            // The sampling bound is the f32 value of 1/√fan_in.
            let bf = (1.0 / (s.fan_in as f32).sqrt()) as f64;
            assert!(w.iter().all(|v| v.abs() <= bf));
            let bias = &p[s.b_off..s.b_off + s.fan_out];
            assert!(bias.iter().all(|v| (v.abs() as f64) <= bf));
        }
        // Padding stays zero.
        let used: usize = l
            .linears
            .iter()
            .map(|s| s.fan_in * s.fan_out + s.fan_out)
            .sum();
        assert_eq!(p.iter().filter(|v| **v != 0.0).count(), used);
    }
}
