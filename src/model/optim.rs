//! Optimiser settings shared by the Adam kernel (`kernels::adam`) and its CPU twin: Adam
//! hyper-parameters and the 3DGS exponential learning-rate schedule.

/// Adam hyper-parameters (PyTorch defaults except ε, which 3DGS sets to 1e-15).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamHyper {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamHyper {
    fn default() -> Self {
        AdamHyper {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

impl AdamHyper {
    /// Bias corrections `(1 − β1^t, 1 − β2^t)` for 1-based step `t`, computed in f64.
    pub fn bias_corrections(&self, t: u32) -> (f32, f32) {
        let t = t.max(1) as i32;
        (
            (1.0 - (self.beta1 as f64).powi(t)) as f32,
            (1.0 - (self.beta2 as f64).powi(t)) as f32,
        )
    }
}

/// `get_expon_lr_func` of 3DGS / Deformable-3DGS: log-linear interpolation from `lr_init` to
/// `lr_final` over `max_steps`, optionally scaled during the first `lr_delay_steps` by a factor
/// rising from `lr_delay_mult` to 1 along a quarter sine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExpLr {
    pub lr_init: f64,
    pub lr_final: f64,
    pub lr_delay_steps: u32,
    pub lr_delay_mult: f64,
    pub max_steps: u32,
}

impl ExpLr {
    /// Deformable-3DGS's deformation-network schedule: 8e-4·scale → 1.6e-6·scale over
    /// `max_steps` (position lr × 5, no delay). `scale` is the scene extent.
    pub fn deform(scale: f64, max_steps: u32) -> Self {
        ExpLr {
            lr_init: 0.00016 * 5.0 * scale,
            lr_final: 0.0000016 * scale,
            lr_delay_steps: 0,
            lr_delay_mult: 0.01,
            max_steps,
        }
    }

    /// Learning rate at `step` (0 before step 0 or when both rates are 0).
    pub fn at(&self, step: i64) -> f64 {
        if step < 0 || (self.lr_init == 0.0 && self.lr_final == 0.0) {
            return 0.0;
        }
        let delay = if self.lr_delay_steps > 0 {
            let r = (step as f64 / self.lr_delay_steps as f64).clamp(0.0, 1.0);
            self.lr_delay_mult + (1.0 - self.lr_delay_mult) * (0.5 * std::f64::consts::PI * r).sin()
        } else {
            1.0
        };
        let t = (step as f64 / self.max_steps.max(1) as f64).clamp(0.0, 1.0);
        delay * (self.lr_init.ln() * (1.0 - t) + self.lr_final.ln() * t).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_lr_matches_3dgs_formula() {
        let s = ExpLr {
            lr_init: 1e-3,
            lr_final: 1e-5,
            lr_delay_steps: 100,
            lr_delay_mult: 0.1,
            max_steps: 1000,
        };
        assert_eq!(s.at(-1), 0.0);
        assert!(
            (s.at(0) - 1e-4).abs() < 1e-12,
            "delay_mult · lr_init at step 0"
        );
        // Past the delay: pure log-linear; half way is the geometric mean.
        assert!((s.at(500) - 1e-4).abs() < 1e-12);
        assert!((s.at(1000) - 1e-5).abs() < 1e-15);
        assert!((s.at(5000) - 1e-5).abs() < 1e-15, "clamped after max_steps");
        let mid = 0.1 + 0.9 * (0.25 * std::f64::consts::PI).sin();
        let want = mid * (1e-3f64.ln() * 0.95 + 1e-5f64.ln() * 0.05).exp();
        assert!((s.at(50) - want).abs() < 1e-15);
        let z = ExpLr {
            lr_init: 0.0,
            lr_final: 0.0,
            ..s
        };
        assert_eq!(z.at(10), 0.0);
        let nd = ExpLr {
            lr_delay_steps: 0,
            ..s
        };
        assert!((nd.at(0) - 1e-3).abs() < 1e-15);
    }
}
