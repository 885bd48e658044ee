//! Optimiser and density control: Adam over the Gaussian sections and the MLP with the plan's
//! learning rates, and 3DGS densification (statistics every step, clone/split/prune and
//! opacity reset at their cadence).

use super::render::RenderPass;
use crate::error::Result;
use crate::kernels::adam::{Adam, AdamBuffers, AdamGroup};
use crate::kernels::densify::{Densifier, DensifyBuffers, DensifySettings, GaussianBuffers};
use crate::kernels::temporal::Temporal;
use crate::model::gaussians::Section;
use crate::model::optim::AdamHyper;
use crate::model::state::{GaussianState, Model, TransientShape};
use crate::train::config::DensifyConfig;
use crate::train::plan::StepLr;
use crate::train::population::{Population, Reserve};
use crate::vk::{BufSlice, Gpu, Recorder};

pub struct AdamPass {
    adam: Adam,
}

impl AdamPass {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(AdamPass {
            adam: Adam::new(gpu)?,
        })
    }

    /// One Adam step of iteration `it` for every Gaussian section (and the MLP while it
    /// trains), skipped on the GPU when a flag of `skip` (the step's render overflows) is set.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        lr: &StepLr,
        it: u32,
        skip: BufSlice<'_>,
    ) {
        let g = &model.gaussians;
        let l = &g.layout;
        let group = |s: Section, lr: f64| AdamGroup {
            first: l.offset(s) as u32,
            count: g.n * l.row_len(s),
            lr: lr as f32,
            mask: None,
        };
        let mut groups = vec![
            group(Section::Means, lr.means),
            group(Section::LogScales, lr.log_scales),
            group(Section::Quats, lr.quats),
            group(Section::Opacity, lr.opacity),
            group(Section::ShDc, lr.sh_dc),
        ];
        if l.sh_coeffs > 1 {
            groups.push(group(Section::ShRest, lr.sh_rest));
        }
        for p in Population::of(g) {
            groups.extend(p.own_groups(l, lr));
        }
        groups.retain(|g| g.count > 0);
        let bufs = AdamBuffers {
            params: g.params.all(),
            grads: g.grads.all(),
            m: g.m.all(),
            v: g.v.all(),
        };
        let h = AdamHyper::default();
        self.adam.record_guarded(rec, bufs, &groups, &h, it, skip);
        if let Some((deform_lr, step)) = lr.deform {
            let d = &model.deform;
            let groups = [AdamGroup {
                first: 0,
                count: d.layout.total as u32,
                lr: deform_lr as f32,
                mask: None,
            }];
            let bufs = AdamBuffers {
                params: d.params.all(),
                grads: d.grads.all(),
                m: d.m.all(),
                v: d.v.all(),
            };
            self.adam.record_guarded(rec, bufs, &groups, &h, step, skip);
            if let Some(ns) = model.nodes.as_ref().filter(|n| n.placed()) {
                // Positions at the Gaussian means' rate (same units), log-radii at their own.
                let m = ns.m;
                let groups = [
                    AdamGroup {
                        first: 0,
                        count: 3 * m,
                        lr: lr.means as f32,
                        mask: None,
                    },
                    AdamGroup {
                        first: 3 * m,
                        count: m,
                        lr: ns.cfg.radius_lr as f32,
                        mask: None,
                    },
                ];
                let bufs = AdamBuffers {
                    params: ns.params.all(),
                    grads: ns.grads.all(),
                    m: ns.adam_m.all(),
                    v: ns.adam_v.all(),
                };
                self.adam.record_guarded(rec, bufs, &groups, &h, step, skip);
            }
        }
    }
}

/// 3DGS density control over the model's Gaussians. Transients are densified with the
/// canonical rows by the same rules (their rows stay after the canonical ones: densification
/// writes rows in their originals' order), pruned by their largest opacity over the sequence,
/// and left alone by the opacity reset.
pub struct DensifyPass {
    densifier: Densifier,
    pub bufs: DensifyBuffers,
    cfg: DensifyConfig,
    /// Rows kept free for transients.
    reserve: Reserve,
    extent: f32,
    seed: u32,
    temporal: Temporal,
    /// The prune's logits [budget] when the model has transients.
    peak: crate::vk::Buffer,
}

impl DensifyPass {
    pub fn new(
        gpu: &Gpu,
        cfg: DensifyConfig,
        reserve: Reserve,
        extent: f32,
        seed: u64,
    ) -> Result<Self> {
        let densifier = Densifier::new(gpu)?;
        Ok(DensifyPass {
            bufs: densifier.buffers(gpu, cfg.budget)?,
            densifier,
            cfg,
            reserve,
            extent,
            seed: seed as u32,
            temporal: Temporal::new(gpu)?,
            peak: gpu.buffer("densify prune logits", cfg.budget.max(1) as u64 * 4)?,
        })
    }

    /// Accumulates the view-space gradient statistics of `render`'s last backward, unless a
    /// flag of `skip` is set (an overflowed step is discarded and re-run: it adds nothing).
    pub fn record_stats(
        &self,
        rec: &mut Recorder<'_>,
        render: &RenderPass,
        n: u32,
        skip: BufSlice<'_>,
    ) {
        let abs = self.cfg.grad_stat == crate::train::config::GradStat::Abs;
        self.densifier
            .record_stats(rec, &self.bufs, &render.bufs, n, Some(skip), abs);
    }

    /// Clone/split/prune into the next generation and make it current (reads the new count
    /// back: this runs every hundred steps, between steps). `screen_cut`: the size prunes
    /// (screen and world, each when configured) are due.
    pub fn densify(
        &self,
        gpu: &Gpu,
        g: &mut GaussianState,
        transient: TransientShape,
        it: u32,
        screen_cut: bool,
    ) -> Result<()> {
        let d = &self.cfg;
        // Growth stops where it would eat into the transients' free share.
        let reserve = self.reserve.rows(g);
        let mut s = DensifySettings::new(self.extent, d.budget.saturating_sub(reserve).max(g.n));
        s.grad_threshold = d.grad_threshold;
        s.percent_dense = d.percent_dense;
        s.min_opacity = d.min_opacity;
        s.max_screen_size = if screen_cut { d.max_screen_size } else { 0.0 };
        s.max_world_size = if screen_cut {
            d.max_world_size * self.extent
        } else {
            0.0
        };
        s.seed = self.seed;
        s.iteration = it;
        let mut rec = Recorder::new(gpu)?;
        let src = GaussianBuffers {
            layout: &g.layout,
            params: &g.params,
            m: &g.m,
            v: &g.v,
        };
        let dst = GaussianBuffers {
            layout: &g.layout,
            params: &g.next[0],
            m: &g.next[1],
            v: &g.next[2],
        };
        let first = g.transient_rows().start;
        let out = self.peak.slice(0, g.n.max(1) as u64 * 4);
        let prune = Population::of(g)
            .iter()
            .find_map(|p| p.record_prune_logits(&mut rec, g, (&self.temporal, transient), out));
        self.densifier
            .record_densify_pruning(&mut rec, &self.bufs, src, dst, g.n, &s, prune)?;
        rec.finish()?;
        let n = self.bufs.read_count(gpu)?;
        let canonical = self.bufs.read_rows_before(gpu, first, g.n)?;
        g.swap_generation(n, n - canonical);
        Ok(())
    }

    /// Zeroes the statistics of rows `first..first + count` (new transients).
    pub fn clear_stats(&self, gpu: &Gpu, first: u32, count: u32) -> Result<()> {
        if count == 0 {
            return Ok(());
        }
        let mut rec = Recorder::new(gpu)?;
        for b in [
            &self.bufs.grad_accum,
            &self.bufs.denom,
            &self.bufs.max_radii,
        ] {
            rec.fill(b.elems::<f32>(first as u64, count as u64), 0);
        }
        rec.finish()?;
        Ok(())
    }

    /// 3DGS's periodic opacity reset (moments of the opacity section cleared), over the
    /// canonical rows: a young transient would not survive it (its life is a few frames, its
    /// opacity would not climb back before the next densification prunes it).
    pub fn reset_opacity(&self, gpu: &Gpu, g: &GaussianState) -> Result<()> {
        let mut rec = Recorder::new(gpu)?;
        let b = GaussianBuffers {
            layout: &g.layout,
            params: &g.params,
            m: &g.m,
            v: &g.v,
        };
        for p in Population::of(g).iter().filter(|p| p.resets_opacity()) {
            debug_assert_eq!(p.rows().start, 0, "the reset runs over rows 0..count");
            self.densifier
                .record_opacity_reset(&mut rec, b, p.rows().len());
        }
        rec.finish()?;
        Ok(())
    }

    /// The statistics (gradient accumulator, count, max radius) of rows `0..n`, for checkpoints.
    pub fn stats(&self, gpu: &Gpu, n: u32) -> Result<[Vec<f32>; 3]> {
        let b = &self.bufs;
        let rd = |x: &crate::vk::Buffer| gpu.read::<f32>(x.elems::<f32>(0, n as u64));
        Ok([rd(&b.grad_accum)?, rd(&b.denom)?, rd(&b.max_radii)?])
    }

    pub fn restore_stats(&self, gpu: &Gpu, stats: &[Vec<f32>; 3]) -> Result<()> {
        let b = &self.bufs;
        for (buf, v) in [&b.grad_accum, &b.denom, &b.max_radii].iter().zip(stats) {
            gpu.upload(buf.all(), v)?;
        }
        Ok(())
    }
}
