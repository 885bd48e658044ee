//! The model's parameters checked for non-finite values (issue 36: a paper-preset run on an
//! H100 saved a `point_cloud.ply` whose Gaussian 74 had a NaN mean and reported itself ok; the
//! projection culls such a Gaussian, so neither the loss nor a render shows it). The guard runs
//! [`ParamCheck::run`] at every probe render and after the last step: one count per section on
//! the GPU (`kernels::check`), read back with nothing else in flight. A Gaussian with a
//! non-finite parameter drew nothing since the value turned, so it is *retired* (finite, with
//! opacity σ(−20), its Adam moments and densification statistics zeroed; the next opacity prune
//! removes it): the renders are unchanged and the saved model loads. A non-finite deformation
//! weight cannot be repaired (every Gaussian moves by it): the caller stops or rolls back.

use crate::error::Result;
use crate::kernels::check::{NonFinite, NonFiniteCheck};
use crate::model::gaussians::{HostGaussians, Section};

use super::Trainer;

/// A retired Gaussian's opacity logit: σ(−20) ≈ 2·10⁻⁹, below every alpha and prune threshold.
const RETIRED_LOGIT: f32 = -20.0;

/// What one check found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamFault {
    /// Gaussians holding a non-finite parameter (retired), and the first of them.
    pub gaussians: usize,
    pub first_row: Option<usize>,
    /// The sections the non-finite values were in.
    pub sections: Vec<&'static str>,
    /// Non-finite deformation weights (not repairable).
    pub weights: u32,
}

impl ParamFault {
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.gaussians > 0 {
            parts.push(format!(
                "{} Gaussian(s) with non-finite {} (first: row {}), retired (they drew nothing)",
                self.gaussians,
                self.sections.join(", "),
                self.first_row.unwrap_or(0)
            ));
        }
        if self.weights > 0 {
            parts.push(format!("{} non-finite deformation weight(s)", self.weights));
        }
        parts.join("; ")
    }
}

fn section_name(s: Section) -> &'static str {
    match s {
        Section::Means => "means",
        Section::LogScales => "log scales",
        Section::Quats => "rotations",
        Section::Opacity => "opacities",
        Section::ShDc => "colours (SH DC)",
        Section::ShRest => "colours (SH rest)",
        Section::TimeCentre => "time centres",
        Section::TimeLogWidth => "time widths",
        Section::Velocity => "velocities",
    }
}

pub struct ParamCheck {
    check: NonFiniteCheck,
}

/// The MLP's slot, after one per section.
const WEIGHTS: usize = Section::ALL.len();

impl ParamCheck {
    pub fn new(gpu: &crate::vk::Gpu) -> Result<Self> {
        Ok(ParamCheck {
            check: NonFiniteCheck::new(gpu, WEIGHTS as u32 + 1)?,
        })
    }

    /// Counts the non-finite parameters; retires the Gaussians holding any. `None` when all
    /// are finite.
    pub fn run(&self, tr: &mut Trainer<'_>) -> Result<Option<ParamFault>> {
        let found = self.count(tr)?;
        if found.iter().all(|f| f.count == 0) {
            return Ok(None);
        }
        let mut fault = ParamFault {
            weights: found[WEIGHTS].count,
            ..ParamFault::default()
        };
        for (k, s) in Section::ALL.iter().enumerate() {
            if found[k].count > 0 {
                fault.sections.push(section_name(*s));
            }
        }
        if found[..WEIGHTS].iter().any(|f| f.count > 0) {
            let mut c = tr.checkpoint()?;
            let rows = bad_rows(&c.model.gaussians);
            for &i in &rows {
                retire(&mut c.model.gaussians, i);
                zero_row(&mut c.model.gauss_m, i);
                zero_row(&mut c.model.gauss_v, i);
                for stat in &mut c.densify_stats {
                    stat[i] = 0.0;
                }
            }
            // Moments of finite rows can hold a non-finite value the next step would pass on.
            for i in bad_rows(&c.model.gauss_m)
                .into_iter()
                .chain(bad_rows(&c.model.gauss_v))
            {
                zero_row(&mut c.model.gauss_m, i);
                zero_row(&mut c.model.gauss_v, i);
            }
            fault.gaussians = rows.len();
            fault.first_row = rows.first().copied();
            if fault.weights == 0 {
                tr.restore(&c)?;
            }
        }
        Ok(Some(fault))
    }

    fn count(&self, tr: &Trainer<'_>) -> Result<Vec<NonFinite>> {
        let gpu = tr.gpu;
        let g = &tr.model.gaussians;
        let first_transient = g.transient_rows().start;
        let mut rec = crate::vk::Recorder::new(gpu)?;
        self.check.reset(&mut rec);
        for (k, &s) in Section::ALL.iter().enumerate() {
            let len = g.layout.row_len(s);
            // The temporal sections are learnt (and written) for transient rows only.
            let first = if Section::TEMPORAL.contains(&s) {
                first_transient
            } else {
                0
            };
            let count = (g.n - first) * len;
            self.check
                .count(&mut rec, g.param(s), first * len, count, k as u32);
        }
        let w = tr.model.deform.params.all();
        self.check
            .count(&mut rec, w, 0, (w.size / 4) as u32, WEIGHTS as u32);
        rec.finish()?;
        self.check.read(gpu)
    }
}

/// Rows holding a non-finite value in any field.
pub fn bad_rows(g: &HostGaussians) -> Vec<usize> {
    let rest = 3 * (g.sh_coeffs as usize).saturating_sub(1);
    let bad = |v: &[f32]| v.iter().any(|x| !x.is_finite());
    (0..g.len())
        .filter(|&i| {
            bad(&g.means[i])
                || bad(&g.log_scales[i])
                || bad(&g.quats[i])
                || !g.opacity[i].is_finite()
                || bad(&g.sh_dc[i])
                || bad(g.sh_rest.get(i * rest..(i + 1) * rest).unwrap_or(&[]))
                || g.time.get(i).is_some_and(|t| bad(t))
                || g.velocity.get(i).is_some_and(|v| bad(v))
        })
        .collect()
}

/// Row `i` made finite and invisible: at the origin, 10⁻⁴ wide, unrotated, opacity σ(−20),
/// black, still (a transient keeps a finite centre and width).
pub fn retire(g: &mut HostGaussians, i: usize) {
    zero_row(g, i);
    g.log_scales[i] = [(1e-4f32).ln(); 3];
    g.quats[i] = [1.0, 0.0, 0.0, 0.0];
    g.opacity[i] = RETIRED_LOGIT;
}

/// Every field of row `i` set to 0 (Adam moments).
pub fn zero_row(g: &mut HostGaussians, i: usize) {
    let rest = 3 * (g.sh_coeffs as usize).saturating_sub(1);
    g.means[i] = [0.0; 3];
    g.log_scales[i] = [0.0; 3];
    g.quats[i] = [0.0; 4];
    g.opacity[i] = 0.0;
    g.sh_dc[i] = [0.0; 3];
    g.sh_rest[i * rest..(i + 1) * rest].fill(0.0);
    if let Some(t) = g.time.get_mut(i) {
        *t = [0.0; 2];
    }
    if let Some(v) = g.velocity.get_mut(i) {
        *v = [0.0; 3];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two(sh_coeffs: u32) -> HostGaussians {
        let rest = 3 * (sh_coeffs as usize - 1);
        HostGaussians {
            sh_coeffs,
            means: vec![[0.1, 0.2, 0.3]; 2],
            log_scales: vec![[-3.0; 3]; 2],
            quats: vec![[0.5, 0.5, 0.5, 0.5]; 2],
            opacity: vec![0.3; 2],
            sh_dc: vec![[0.2; 3]; 2],
            sh_rest: vec![0.01; 2 * rest],
            transients: 0,
            time: Vec::new(),
            velocity: Vec::new(),
        }
    }

    #[test]
    fn finds_every_field_and_retires_to_finite() {
        let clean = two(4);
        assert!(bad_rows(&clean).is_empty());
        let rest = 9;
        type Plant = Box<dyn Fn(&mut HostGaussians)>;
        let cases: Vec<Plant> = vec![
            Box::new(|g| g.means[1][2] = f32::NAN),
            Box::new(|g| g.log_scales[1][0] = f32::INFINITY),
            Box::new(|g| g.quats[1][3] = f32::NEG_INFINITY),
            Box::new(|g| g.opacity[1] = f32::NAN),
            Box::new(|g| g.sh_dc[1][1] = f32::NAN),
            Box::new(move |g| g.sh_rest[rest + rest - 1] = f32::NAN),
            Box::new(|g| {
                g.transients = 1;
                g.time = vec![[0.5, -2.0], [f32::NAN, -2.0]];
                g.velocity = vec![[0.0; 3]; 2];
            }),
            Box::new(|g| {
                g.transients = 1;
                g.time = vec![[0.5, -2.0]; 2];
                g.velocity = vec![[0.0; 3], [0.0, f32::INFINITY, 0.0]];
            }),
        ];
        for (k, plant) in cases.iter().enumerate() {
            let mut g = clean.clone();
            plant(&mut g);
            assert_eq!(bad_rows(&g), vec![1], "case {k}");
            retire(&mut g, 1);
            assert!(bad_rows(&g).is_empty(), "case {k}");
            assert_eq!(g.opacity[1], RETIRED_LOGIT);
            // The other row is untouched.
            assert_eq!(g.means[0], clean.means[0]);
            assert_eq!(g.sh_rest[..rest], clean.sh_rest[..rest]);
        }
    }
}
