//! `dispflow-vk bench field`: the training step with the per-Gaussian MLP (Deformable-3DGS)
//! against the control-node field at 256, 512 and 1024 nodes (docs/nodes.md), same scenes,
//! methods and zones as `bench step`, steps interleaved. Each scene's model is first grown to
//! the Gaussian count a trained run reaches (jittered copies of its points; the cost of a step
//! depends on how many Gaussians there are, not on where), so the MLP's share is the one a
//! real run pays.

use super::step::{rows_of, scenes, time_interleaved, timed_config, StepRow};
use crate::data;
use crate::error::Result;
use crate::model::gaussians::HostGaussians;
use crate::model::nodes::FieldKind;
use crate::train::plan::hash_uniform;
use crate::train::Trainer;
use crate::vk::Gpu;

/// (label, nodes; `None` = the MLP field).
pub const FIELDS: [(&str, Option<u32>); 4] = [
    ("MLP at every Gaussian (--deform-field mlp)", None),
    ("nodes 256", Some(256)),
    ("nodes 512", Some(512)),
    ("nodes 1024", Some(1024)),
];

/// `g` grown to `n` Gaussians by copies of its rows with their means jittered by up to 1 %
/// of the points' spread (deterministic).
pub fn grown(g: &HostGaussians, n: usize) -> HostGaussians {
    let len = g.len();
    let mut out = g.clone();
    if len == 0 {
        return out;
    }
    let (lo, hi) = g
        .means
        .iter()
        .fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), m| {
            (
                std::array::from_fn(|a| lo[a].min(m[a])),
                std::array::from_fn(|a| hi[a].max(m[a])),
            )
        });
    let rest = g.sh_rest.len() / len;
    for i in len..n {
        let s = i % len;
        let jitter = |a: usize| (hash_uniform(11, i as u64, a as u64) as f32 - 0.5) * 0.02;
        let m = g.means[s];
        out.means
            .push(std::array::from_fn(|a| m[a] + jitter(a) * (hi[a] - lo[a])));
        out.log_scales.push(g.log_scales[s]);
        out.quats.push(g.quats[s]);
        out.opacity.push(g.opacity[s]);
        out.sh_dc.push(g.sh_dc[s]);
        out.sh_rest
            .extend_from_slice(&g.sh_rest[s * rest..(s + 1) * rest]);
    }
    out
}

/// Times `steps` steps (after `warm`) of each scene × method × field at `gaussians`
/// Gaussians (0: the scene's initial points).
pub fn run_field_bench(gpu: &Gpu, warm: u32, steps: u32, gaussians: u32) -> Result<Vec<StepRow>> {
    let mut rows = Vec::new();
    for (scene, dir) in scenes()? {
        for (method, weight) in [("baseline", 0.0f32), ("DispFlow", 0.1)] {
            let mut cfg = timed_config(weight);
            cfg.densify.budget = cfg.densify.budget.max(gaussians);
            let data = data::load(&dir, &cfg.load_options())?;
            let mut trainers = Vec::new();
            for (_, nodes) in FIELDS {
                let mut c = cfg.clone();
                c.deform_field.kind = FieldKind::Mlp;
                if let Some(m) = nodes {
                    c.deform_field.kind = FieldKind::Nodes;
                    c.deform_field.nodes = m;
                }
                let mut tr = Trainer::new(gpu, &c, &data)?;
                if gaussians > 0 {
                    let g = grown(&tr.gaussians()?, gaussians as usize);
                    tr.model.gaussians.upload(gpu, &g, "bench Gaussians")?;
                }
                tr.step(false, false)?; // builds the passes, places the nodes
                trainers.push(tr);
            }
            let times = time_interleaved(&mut trainers, warm, steps)?;
            let labels = FIELDS.iter().map(|f| f.0);
            rows.extend(rows_of(&scene, method, &trainers, times, labels));
        }
    }
    Ok(rows)
}
