//! Quality against time: the test-PSNR probe frames, the worst training view of a log
//! interval (a collapse shows as one view far below the rest), time-to-X-dB from a run's
//! `log.jsonl`, and the PSNR-vs-wall-seconds plot.

use serde::{Deserialize, Serialize};

use super::outputs::LogLine;
use crate::error::Result;
use crate::report::{Plot, Series, PALETTE};

/// Test frames the periodic probe renders: at most 8, spread evenly over the test split
/// (time order of the split), so the curve costs a few renders whatever the split's size.
/// Four were too few: on mujoco-scene7 they read 23.89 dB where all 27 test frames give 21.58.
pub fn probe_frames(n: usize) -> Vec<usize> {
    const K: usize = 8;
    if n <= K {
        return (0..n).collect();
    }
    (0..K).map(|i| i * (n - 1) / (K - 1)).collect()
}

/// What the periodic probe measured: means over its frames (each over the frames that have
/// it; `None` where none does).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Probe {
    pub psnr: f64,
    pub dynamic_psnr: Option<f64>,
    pub static_psnr: Option<f64>,
    /// Displacement EPE inside the masks (pixels), the ground-truth flow's mean length there
    /// (the EPE of a motionless model) and the Gaussians' projected-motion quantiles.
    pub epe: Option<f64>,
    pub gt_px: Option<f64>,
    pub p50_px: Option<f64>,
    pub p99_px: Option<f64>,
}

impl Probe {
    pub fn of(
        frames: &[crate::train::score::FrameEval],
        motion: &[crate::train::score::epe::MotionProbe],
    ) -> Self {
        use crate::train::metrics::mean_some as mean_of;
        Probe {
            psnr: crate::train::metrics::mean(frames.iter().map(|f| f.psnr)),
            dynamic_psnr: mean_of(frames.iter().map(|f| f.dynamic_psnr)),
            static_psnr: mean_of(frames.iter().map(|f| f.static_psnr)),
            epe: mean_of(motion.iter().map(|m| m.epe)),
            gt_px: mean_of(motion.iter().map(|m| m.gt_len)),
            p50_px: mean_of(motion.iter().map(|m| m.p50)),
            p99_px: mean_of(motion.iter().map(|m| m.p99)),
        }
    }
}

impl Probe {
    /// The progress line's part: ` test(K) P (dyn D / static S) epe E/G px`, K the probe's
    /// frame count (the final test PSNR is over every test frame, so it differs).
    pub fn summary(&self, frames: usize) -> String {
        let mut s = format!(" test({frames}) {:.2}", self.psnr);
        if let (Some(d), Some(st)) = (self.dynamic_psnr, self.static_psnr) {
            s += &format!(" (dyn {d:.2} / static {st:.2})");
        }
        if let (Some(e), Some(g)) = (self.epe, self.gt_px) {
            s += &format!(" epe {e:.2}/{g:.2} px");
        }
        s
    }
}

/// The worst training view seen since the last log line.
#[derive(Clone, Debug, Default)]
pub struct WorstView {
    worst: Option<(f64, String)>,
}

impl WorstView {
    pub fn see(&mut self, psnr: f64, id: &str) {
        // A NaN PSNR is the worst there is.
        let worse = match &self.worst {
            None => true,
            Some((w, _)) => psnr.is_nan() || psnr < *w,
        };
        if worse && !self.worst.as_ref().is_some_and(|(w, _)| w.is_nan()) {
            self.worst = Some((psnr, id.to_string()));
        }
    }

    /// The worst view of the interval, starting a new interval.
    pub fn take(&mut self) -> Option<(f64, String)> {
        self.worst.take()
    }
}

/// Test PSNR first reached at a wall time (the probe's mean over [`probe_frames`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimeTo {
    pub psnr_db: f64,
    /// Training seconds (steps only, across resumes) when the probe first read ≥ `psnr_db`.
    pub wall_s: f64,
    pub iteration: u32,
}

/// Thresholds reported in `metrics.json` (`time_to_psnr`).
pub const THRESHOLDS_DB: [f64; 7] = [15.0, 18.0, 20.0, 22.0, 25.0, 28.0, 30.0];

/// For each threshold the probe reached, the first log line that read at least it.
pub fn time_to_psnr(log: &[LogLine]) -> Vec<TimeTo> {
    THRESHOLDS_DB
        .iter()
        .filter_map(|&db| {
            log.iter()
                .find(|l| l.test_psnr.is_some_and(|p| p >= db))
                .map(|l| TimeTo {
                    psnr_db: db,
                    wall_s: l.wall_s,
                    iteration: l.iteration,
                })
        })
        .collect()
}

/// Test PSNR against training seconds, one curve per labelled log.
pub fn psnr_time_plot(
    runs: &[(String, &[LogLine])],
    width: u32,
    height: u32,
) -> Result<image::RgbImage> {
    let series = runs
        .iter()
        .enumerate()
        .map(|(i, (label, log))| Series {
            label: label.clone(),
            points: log
                .iter()
                .filter_map(|l| l.test_psnr.map(|p| (l.wall_s, p)))
                .collect(),
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    Plot {
        title: "test PSNR against training time".into(),
        x_label: "training seconds".into(),
        y_label: "test PSNR (dB)".into(),
        series,
        width,
        height,
    }
    .render()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(iteration: u32, wall_s: f64, test_psnr: Option<f64>) -> LogLine {
        LogLine {
            iteration,
            loss: 0.1,
            psnr: 20.0,
            num_gaussians: 1,
            motion_weight: 0.0,
            ms: 1.0,
            dynamic_fraction: 1.0,
            wall_s,
            test_psnr,
            ..LogLine::default()
        }
    }

    #[test]
    fn probe_frames_spread_over_the_split() {
        assert_eq!(probe_frames(0), Vec::<usize>::new());
        assert_eq!(probe_frames(3), vec![0, 1, 2]);
        assert_eq!(probe_frames(8), (0..8).collect::<Vec<_>>());
        assert_eq!(probe_frames(15), vec![0, 2, 4, 6, 8, 10, 12, 14]);
    }

    #[test]
    fn time_to_takes_the_first_line_at_or_above() {
        let log = [
            line(50, 5.0, Some(14.0)),
            line(100, 10.0, None),
            line(150, 15.0, Some(18.0)),
            line(200, 20.0, Some(17.0)),
            line(250, 25.0, Some(21.0)),
        ];
        let t = time_to_psnr(&log);
        let got: Vec<(f64, f64, u32)> = t
            .iter()
            .map(|t| (t.psnr_db, t.wall_s, t.iteration))
            .collect();
        assert_eq!(
            got,
            vec![(15.0, 15.0, 150), (18.0, 15.0, 150), (20.0, 25.0, 250)]
        );
    }

    #[test]
    fn worst_view_keeps_the_lowest_and_nan() {
        let mut w = WorstView::default();
        w.see(20.0, "a");
        w.see(12.0, "b");
        w.see(15.0, "c");
        assert_eq!(w.take(), Some((12.0, "b".to_string())));
        assert_eq!(w.take(), None);
        w.see(20.0, "a");
        w.see(f64::NAN, "n");
        w.see(3.0, "c");
        let (p, id) = w.take().unwrap();
        assert!(p.is_nan() && id == "n");
    }
}
