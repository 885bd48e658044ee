//! The `data` subcommand: `data gen` and `data check`.

use std::path::PathBuf;

use super::points::PointsPreference;
use super::synthetic::{self, Preset, SceneMotion};
use super::LoadOptions;

/// Generate or check datasets.
#[derive(clap::Args, Debug)]
pub struct DataArgs {
    #[command(subcommand)]
    pub command: DataCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum DataCommand {
    /// Generate the built-in synthetic scene (nerfies format, plus exact motion masks under
    /// mask/1x and ground-truth 2D scene flow under flow/).
    Gen {
        /// Output directory (created if missing; existing files are overwritten).
        #[arg(long)]
        out: PathBuf,
        /// Size preset: tiny = 64×64, 24 frames; small = 160×120, 60 frames; medium = 480×270,
        /// 150 frames.
        #[arg(long, value_enum, default_value_t = Preset::Tiny)]
        preset: Preset,
        /// Random seed (textures, colours, points); the same seed gives identical files.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// How the objects move (the camera arc is the same in every kind): moving = throughout
        /// the sequence; static = frozen at their t = 0 pose, masks and flow all zero; late = at
        /// rest for the first half, then their whole trajectory in the second half; events = as
        /// moving, plus small spheres that appear (t = 0.35), vanish (t = 0.65) and split in two
        /// (t = 0.5).
        #[arg(long, value_enum, default_value_t = SceneMotion::Moving)]
        motion: SceneMotion,
    },
    /// Load a dataset (nerfies or D-NeRF/blender), validate every file and print a report:
    /// frames per split, time range, resolution, camera spread, masks, points, warnings.
    Check {
        /// Dataset directory.
        dir: PathBuf,
        /// nerfies: use rgb/<s>x; blender: box-downscale by this factor [default: the highest
        /// resolution available].
        #[arg(long)]
        downscale: Option<u32>,
        /// Largest image side after loading, in pixels [default: no limit].
        #[arg(long)]
        max_size: Option<u32>,
        /// Source of initial points.
        #[arg(long, value_enum, default_value_t = PointsPreference::Auto)]
        points: PointsPreference,
    },
}

/// Runs `dispflow-vk data ...`.
pub fn run(args: &DataArgs) -> crate::Result<()> {
    match &args.command {
        DataCommand::Gen {
            out,
            preset,
            seed,
            motion,
        } => {
            let t0 = std::time::Instant::now();
            let s = synthetic::generate_with(*preset, *seed, *motion, out)?;
            println!(
                "wrote {} ({} preset, seed {}, motion {}): {} frames {}×{} (train {}, val {}), \
                 {} points, masks and scene flow, in {:.1} s",
                s.dir.display(),
                s.preset.name(),
                s.seed,
                s.motion.name(),
                s.frames,
                s.width,
                s.height,
                s.train,
                s.val,
                s.points,
                t0.elapsed().as_secs_f64()
            );
        }
        DataCommand::Check {
            dir,
            downscale,
            max_size,
            points,
        } => {
            let opts = LoadOptions {
                downscale: *downscale,
                max_size: *max_size,
                points: *points,
                ..LoadOptions::default()
            };
            print!("{}", super::check::report(dir, &opts)?);
        }
    }
    Ok(())
}
