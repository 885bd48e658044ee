//! LPIPS: one image pair per run, the whole network (input, 5 convs, 2 pools, 5 stage diffs).

use super::*;

use crate::train::score::lpips::{random_weights, LpipsScorer};

/// `WIDTHxHEIGHT` → (width, height).
pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let bad = || {
        Error::Invalid(format!(
            "--lpips-sizes {s:?}: expected WIDTHxHEIGHT, e.g. 480x270"
        ))
    };
    let (w, h) = s.split_once(['x', '×']).ok_or_else(bad)?;
    Ok((
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    ))
}

/// LPIPS of two random `width`×`height` images with random AlexNet weights.
pub struct LpipsCase {
    scorer: std::cell::RefCell<LpipsScorer>,
    imgs: [Buffer; 2],
    pub size: (u32, u32),
}

impl LpipsCase {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> Result<Self> {
        let mut noise = Noise::new(0x1b1b5);
        let mut img = |name: &str| {
            let px: Vec<f32> = (0..4 * width as usize * height as usize)
                .map(|_| (noise.next_u32() >> 8) as f32 / 16_777_216.0)
                .collect();
            gpu.buffer_from(name, &px)
        };
        let imgs = [img("bench lpips img0")?, img("bench lpips img1")?];
        let mut scorer = LpipsScorer::new(gpu, random_weights(3))?;
        // Allocates the scratch outside the timed runs.
        scorer.score(gpu, (width, height), imgs[0].all(), imgs[1].all())?;
        Ok(LpipsCase {
            scorer: std::cell::RefCell::new(scorer),
            imgs,
            size: (width, height),
        })
    }

    pub fn run(&self, gpu: &Gpu) -> Result<Timings> {
        let mut rec = Recorder::timed(gpu)?;
        let (a, b) = (self.imgs[0].all(), self.imgs[1].all());
        self.scorer.borrow_mut().record(&mut rec, self.size, a, b)?;
        rec.finish()
    }

    /// Runs once and checks the value: against the CPU twin up to 96×96 (the f64 twin of a
    /// large image takes minutes), finite and positive above.
    pub fn verify(&self, gpu: &Gpu) -> Result<f64> {
        self.run(gpu)?;
        let got = self.scorer.borrow().value(gpu)?;
        let (w, h) = self.size;
        let ok = if w * h <= 96 * 96 {
            let px = |i: usize| -> Result<Vec<[f32; 4]>> { gpu.read(self.imgs[i].all()) };
            let s = self.scorer.borrow();
            let want: f64 =
                reference::lpips::lpips(s.weights(), &px(0)?, &px(1)?, w as usize, h as usize)?
                    .iter()
                    .sum();
            (got - want).abs() <= 1e-6 + 1e-4 * want
        } else {
            got.is_finite() && got > 0.0
        };
        if !ok {
            return Err(Error::Invalid(format!("bench: LPIPS {w}×{h} gave {got}")));
        }
        Ok(got)
    }
}
