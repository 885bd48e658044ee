//! `dispflow-vk signal`: how good is the scene motion a motion step would learn from, at some
//! stage of a run? For training frames with motion masks, the probe draws what a direct-order
//! step draws (render (v1, t1) and the intermediate (v1, t2), t2 the frame's pair), measures
//! the scene motion with each variant of the estimator and its correction, and scores the
//! min-max normalised magnitude against the mask (AP; the mean over frames is `flow_mmap`),
//! next to the oracle (the scene's ground-truth flow, synthetic scenes) and the model's own
//! displacement flow. It also reports the confidence inside and outside the masks, since a
//! confidence that distrusts exactly the moving pixels would erase the signal it filters.

use std::path::PathBuf;

use serde::Serialize;

use super::run::open_run;
use crate::data;
use crate::error::{Error, Result};
use crate::kernels::dispflow::DispFlow;
use crate::kernels::flow::FlowConfig;
use crate::kernels::metrics::{MetricBuffers, MotionMetrics};
use crate::kernels::motion::{MotionNorm, NormBuffers, NormConfig};
use crate::kernels::raster::RenderOpts;
use crate::train::checkpoint::{is_kept_checkpoint, write_atomic, Checkpoint};
use crate::train::config::SceneMotionConfig;
use crate::train::frames::{attach_gt_flow, attach_masks, GpuFrame};
use crate::train::passes::motion::{OpticalFlow, OracleFlow};
use crate::train::passes::{
    DeformPass, MotionPair, OverflowWatch, RenderPass, SceneMotion, SceneSignal, Slot,
};
use crate::train::score::ModelView;
use crate::train::step::ALPHA_MAX;
use crate::train::Trainer;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

#[derive(clap::Args, Debug, Clone)]
pub struct SignalArgs {
    /// Run directory written by `dispflow-vk train` (its config.toml and dataset).
    #[arg(long)]
    pub run: PathBuf,
    /// Checkpoints to score (repeat) [default: every RUN/checkpoints/NNNNNN.ckpt, written by
    /// `train --keep-checkpoints`, else RUN/checkpoints/last.ckpt].
    #[arg(long)]
    pub checkpoint: Vec<PathBuf>,
    /// Dataset directory [default: the one recorded in the run's metrics.json].
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Training frames with a non-empty motion mask to score, spread evenly [default: 16].
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Confidence σ whose inside/outside-mask means are reported [default: 0.1].
    #[arg(long, default_value_t = 0.1)]
    pub sigma: f32,
    /// Where the JSON goes [default: RUN/signal.json].
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Where the Markdown table goes [default: RUN/signal.md].
    #[arg(long)]
    pub table: Option<PathBuf>,
}

/// One way of measuring the scene motion.
#[derive(Clone, Debug)]
pub struct Variant {
    pub name: String,
    pub motion: SceneMotionConfig,
    pub flow_preset: &'static str,
    /// Flow render (v1, t1) → render (v1, t2) instead of photo → render (the model's change
    /// alone; what the residual correction approximates).
    pub render_pair: bool,
}

/// The variants `signal` scores: each knob of `[scene_motion]` alone, and the residual with
/// each data-term knob.
pub fn variants() -> Vec<Variant> {
    let m = |f: &dyn Fn(&mut SceneMotionConfig)| {
        let mut c = SceneMotionConfig::default();
        f(&mut c);
        c
    };
    let v = |name: &str, motion, flow_preset, render_pair| Variant {
        name: name.into(),
        motion,
        flow_preset,
        render_pair,
    };
    vec![
        v("photo → render t2 (raw)", m(&|_| ()), "default", false),
        v("raw, fast flow", m(&|_| ()), "fast", false),
        v("raw, level 1", m(&|c| c.level = 1), "default", false),
        v(
            "raw, fast flow, level 1",
            m(&|c| c.level = 1),
            "fast",
            false,
        ),
        v(
            "raw, blur photo 2",
            m(&|c| c.blur_photo = 2),
            "default",
            false,
        ),
        v(
            "raw, blur photo 6",
            m(&|c| c.blur_photo = 6),
            "default",
            false,
        ),
        v(
            "raw, texture 0.8",
            m(&|c| c.texture = 0.8),
            "default",
            false,
        ),
        v("residual", m(&|c| c.residual = true), "default", false),
        v(
            "residual, blur photo 2",
            m(&|c| {
                c.residual = true;
                c.blur_photo = 2
            }),
            "default",
            false,
        ),
        v(
            "residual, texture 0.8",
            m(&|c| {
                c.residual = true;
                c.texture = 0.8
            }),
            "default",
            false,
        ),
        v(
            "residual, level 1",
            m(&|c| {
                c.residual = true;
                c.level = 1
            }),
            "default",
            false,
        ),
        v("render t1 → render t2", m(&|_| ()), "default", true),
    ]
}

/// The scores of one checkpoint.
#[derive(Clone, Debug, Serialize)]
pub struct SignalScores {
    pub checkpoint: String,
    pub iteration: u32,
    pub frames: usize,
    /// (variant, mean AP over the frames).
    pub flow_mmap: Vec<(String, f64)>,
    /// The ground-truth flow's mean AP (synthetic scenes).
    pub oracle: Option<f64>,
    /// The model's own displacement flow δ (t1 → t2), splatted by the render at (v1, t1).
    pub model_delta: f64,
    /// Mean confidence at σ inside and outside the masks.
    pub confidence_in: f64,
    pub confidence_out: f64,
}

/// Scratch for probing one model: its own deformation and the two renders.
struct Probe {
    deform: DeformPass,
    r1: RenderPass,
    r2: RenderPass,
    watch: OverflowWatch,
    dispflow: DispFlow,
    delta: Buffer,
}

/// Normalises a field's magnitude and scores it against a mask.
struct Scorer {
    norm: MotionNorm,
    disp_norm: NormBuffers,
    flow_norm: NormBuffers,
    metrics: MotionMetrics,
    ap: MetricBuffers,
}

impl Scorer {
    /// AP of the min-max normalised magnitude of `field` (`ch` = 2 or 3 channels).
    fn ap(
        &mut self,
        gpu: &Gpu,
        record: impl FnOnce(&mut Recorder<'_>),
        field: BufSlice<'_>,
        ch: u32,
        mask: BufSlice<'_>,
    ) -> Result<f64> {
        let mut rec = Recorder::new(gpu)?;
        record(&mut rec);
        let nb = if ch == 3 {
            &mut self.disp_norm
        } else {
            &mut self.flow_norm
        };
        self.norm.record(&mut rec, nb, field, NormConfig::default());
        self.metrics.record_ap(&mut rec, &self.ap, nb.m_hat(), mask);
        rec.finish()?;
        Ok(self.ap.ap(gpu)?.unwrap_or(0.0))
    }
}

fn scene_signal(
    gpu: &Gpu,
    tr: &Trainer<'_>,
    v: &Variant,
    sigma: f32,
) -> Result<(SceneSignal, Box<dyn SceneMotion>)> {
    let flow = v.motion.flow_config(v.flow_preset)?;
    let mut sig = v.motion.signal();
    sig.sigma = sigma;
    let make = |f: FlowConfig| -> Result<Box<dyn SceneMotion>> {
        Ok(Box::new(OpticalFlow::new(gpu, f, &tr.sizes)?))
    };
    Ok((
        SceneSignal::new(gpu, make(flow)?, sig, tr.sizes.pixels())?,
        make(flow)?,
    ))
}

/// `signal`: scores every checkpoint; writes JSON and a Markdown table.
pub fn run_signal(a: &SignalArgs) -> Result<Vec<SignalScores>> {
    let run = open_run(&a.run, a.data.as_deref())?;
    let ckpts = checkpoints(a)?;
    let gpu = Gpu::new_default()?;
    let ds = data::load(&run.data_dir, &run.cfg.load_options())?;
    let mut out = Vec::new();
    for path in &ckpts {
        let mut tr = Trainer::new(&gpu, &run.cfg, &ds)?;
        let c = Checkpoint::load(path)?;
        tr.restore(&c)
            .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
        attach_masks(&gpu, &mut tr.frames, &ds)?;
        let oracle = attach_gt_flow(&gpu, &mut tr.frames, &ds).is_ok();
        let s = score(&gpu, &mut tr, a, oracle, &path.display().to_string())?;
        eprintln!(
            "{}: iteration {}, {} frames: oracle {}, model δ {:.4}",
            path.display(),
            s.iteration,
            s.frames,
            s.oracle.map_or("n/a".into(), |v| format!("{v:.4}")),
            s.model_delta
        );
        out.push(s);
    }
    let json = a.json.clone().unwrap_or(a.run.join("signal.json"));
    let text = serde_json::to_string_pretty(&out).map_err(|e| Error::Invalid(e.to_string()))?;
    write_atomic(&json, text.as_bytes())?;
    let md = table(&out);
    let table_path = a.table.clone().unwrap_or(a.run.join("signal.md"));
    write_atomic(&table_path, md.as_bytes())?;
    println!("{md}");
    Ok(out)
}

fn checkpoints(a: &SignalArgs) -> Result<Vec<PathBuf>> {
    if !a.checkpoint.is_empty() {
        return Ok(a.checkpoint.clone());
    }
    let dir = a.run.join("checkpoints");
    let mut kept: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(Error::io(&dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| is_kept_checkpoint(p))
        .collect();
    kept.sort();
    if kept.is_empty() {
        kept.push(dir.join("last.ckpt"));
    }
    Ok(kept)
}

/// Training frames with a non-empty mask, at most `n`, spread evenly.
fn masked_frames(frames: &[GpuFrame], n: usize) -> Vec<usize> {
    let with: Vec<usize> = (0..frames.len())
        .filter(|&i| {
            frames[i]
                .mask
                .as_ref()
                .is_some_and(|m| m.1.iter().any(|&v| v != 0))
        })
        .collect();
    let k = with.len().min(n);
    (0..k).map(|j| with[j * with.len() / k.max(1)]).collect()
}

fn score(
    gpu: &Gpu,
    tr: &mut Trainer<'_>,
    a: &SignalArgs,
    oracle: bool,
    name: &str,
) -> Result<SignalScores> {
    let s = tr.sizes;
    let (w, h) = (s.width, s.height);
    let norm = MotionNorm::new(gpu)?;
    let metrics = MotionMetrics::new(gpu)?;
    let raster = tr.raster();
    let mut p = Probe {
        deform: DeformPass::new(
            gpu,
            &tr.model.deform.cfg,
            crate::train::node_cfg(&tr.model),
            &s,
            2,
            false,
        )?,
        r1: RenderPass::new(raster.clone(), gpu, &s, 3)?,
        r2: RenderPass::new(raster, gpu, &s, 0)?,
        watch: OverflowWatch::new(gpu, "signal overflow flags", 2)?,
        dispflow: DispFlow::new(gpu)?,
        delta: gpu.buffer("signal displacement", s.capacity as u64 * 12)?,
    };
    let mut sc = Scorer {
        disp_norm: norm.buffers(gpu, w, h, 3)?,
        flow_norm: norm.buffers(gpu, w, h, 2)?,
        ap: metrics.buffers(gpu, w, h)?,
        norm,
        metrics,
    };
    let vars = variants();
    let signals = vars
        .iter()
        .map(|v| scene_signal(gpu, tr, v, a.sigma))
        .collect::<Result<Vec<_>>>()?;
    let view = tr.view();
    let which = masked_frames(&tr.frames, a.frames);
    if which.is_empty() {
        return Err(Error::Invalid(format!(
            "{}: no training frame has a non-empty motion mask; `signal` scores against masks",
            a.run.display()
        )));
    }
    let mut sums = vec![0.0; vars.len()];
    let (mut oracle_sum, mut delta_sum) = (0.0, 0.0);
    let (mut cin, mut cout) = ((0.0, 0usize), (0.0, 0usize));
    for &fi in &which {
        let pair = tr.times.pair(fi, tr.cfg.pair_gap);
        let (fa, fb) = (&tr.frames[fi], &tr.frames[pair]);
        p.render_pair(gpu, tr, view, fa, fb.time)?;
        let mask = fa.mask.as_ref().expect("masked frame").0.all();
        // The model's own displacement flow.
        delta_sum += sc.ap(gpu, |_| (), p.r1.features(), 3, mask)?;
        let photo_pair = MotionPair {
            a: fa,
            b: fb,
            from: fa.target.all(),
            to: p.r2.rgba(),
            render_t1: p.r1.rgba(),
            depth_t1: p.r1.depth(),
        };
        for (k, (v, (sig, plain))) in vars.iter().zip(&signals).enumerate() {
            let record = |rec: &mut Recorder<'_>| {
                if v.render_pair {
                    let mp = MotionPair {
                        from: p.r1.rgba(),
                        ..photo_pair
                    };
                    plain.record(rec, &mp, sig.flow());
                } else {
                    sig.record(rec, &photo_pair, p.r1.rgba());
                }
            };
            sums[k] += sc.ap(gpu, record, sig.flow(), 2, mask)?;
            if let (0, Some(c)) = (k, sig.confidence()) {
                let c: Vec<f32> = gpu.read(c)?;
                let m = &fa.mask.as_ref().expect("masked frame").1;
                for (cv, &mv) in c.iter().zip(m) {
                    let acc = if mv != 0 { &mut cin } else { &mut cout };
                    acc.0 += *cv as f64;
                    acc.1 += 1;
                }
            }
        }
        if oracle {
            let sig = &signals[0].0;
            let record = |rec: &mut Recorder<'_>| OracleFlow.record(rec, &photo_pair, sig.flow());
            oracle_sum += sc.ap(gpu, record, sig.flow(), 2, mask)?;
        }
    }
    let n = which.len() as f64;
    Ok(SignalScores {
        checkpoint: name.to_string(),
        iteration: tr.iteration,
        frames: which.len(),
        flow_mmap: vars
            .iter()
            .zip(&sums)
            .map(|(v, s)| (v.name.clone(), s / n))
            .collect(),
        oracle: oracle.then_some(oracle_sum / n),
        model_delta: delta_sum / n,
        confidence_in: cin.0 / cin.1.max(1) as f64,
        confidence_out: cout.0 / cout.1.max(1) as f64,
    })
}

impl Probe {
    /// Renders (v1, t1) with δ = dx(t2) − dx(t1) as features, and (v1, t2); grows on overflow.
    fn render_pair(
        &mut self,
        gpu: &Gpu,
        tr: &Trainer<'_>,
        view: ModelView,
        fa: &GpuFrame,
        t2: f32,
    ) -> Result<()> {
        let (model, opts) = (
            &tr.model,
            RenderOpts {
                background: tr.background,
                alpha_max: ALPHA_MAX,
                abs_grad: false,
                detach_feature_weights: false,
            },
        );
        let g = &model.gaussians;
        loop {
            let mut rec = Recorder::new(gpu)?;
            let active = view.deform_active;
            self.deform
                .forward(&mut rec, model, Slot::T1, fa.time, active);
            if active {
                self.deform.mlp_forward(&mut rec, model, Slot::T2, t2);
                let (o1, o2) = (self.deform.output(Slot::T1), self.deform.output(Slot::T2));
                self.dispflow
                    .displacement(&mut rec, g.n, o1, o2, self.delta.all());
            } else {
                rec.fill(self.delta.all(), 0);
            }
            self.deform
                .transient_displacement(&mut rec, model, (fa.time, t2), self.delta.all());
            self.deform.apply(&mut rec, model, Slot::T2, t2, active);
            let mut s1 = self.deform.splats(model, Slot::T1, view.sh_degree);
            s1.features = Some((self.delta.all(), 3));
            self.r1.forward(&mut rec, &fa.camera, &s1, &opts);
            let s2 = self.deform.splats(model, Slot::T2, view.sh_degree);
            self.r2.forward(&mut rec, &fa.camera, &s2, &opts);
            self.watch.record(&mut rec, 0, &self.r1);
            self.watch.record(&mut rec, 1, &self.r2);
            self.watch.publish(&mut rec);
            rec.finish()?;
            let (o1, o2) = (
                self.watch.read(0, "signal render at t1")?,
                self.watch.read(1, "signal render at t2")?,
            );
            if !(o1.overflowed || o2.overflowed) {
                return Ok(());
            }
            if o1.overflowed {
                self.r1.grow(gpu, o1.needed)?;
            }
            if o2.overflowed {
                self.r2.grow(gpu, o2.needed)?;
            }
        }
    }
}

/// The Markdown table: a row per variant, a column per checkpoint.
pub fn table(s: &[SignalScores]) -> String {
    let mut t = String::from("| scene motion |");
    for c in s {
        t += &format!(" it {} |", c.iteration);
    }
    t += "\n|---|";
    t += &"---:|".repeat(s.len());
    t += "\n";
    let row = |name: &str, f: &dyn Fn(&SignalScores) -> String| {
        let mut r = format!("| {name} |");
        for c in s {
            r += &format!(" {} |", f(c));
        }
        r + "\n"
    };
    if let Some(first) = s.first() {
        for (k, (name, _)) in first.flow_mmap.iter().enumerate() {
            t += &row(name, &|c| format!("{:.4}", c.flow_mmap[k].1));
        }
    }
    t += &row("oracle (ground-truth flow)", &|c| {
        c.oracle.map_or("n/a".into(), |v| format!("{v:.4}"))
    });
    t += &row("model's displacement flow δ", &|c| {
        format!("{:.4}", c.model_delta)
    });
    t += &row("confidence inside / outside masks", &|c| {
        format!("{:.2} / {:.2}", c.confidence_in, c.confidence_out)
    });
    t
}
