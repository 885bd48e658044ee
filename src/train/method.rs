//! The paper's comparisons as configuration (issue 17): the motion representation, the scene
//! motion it is supervised with, the weight schedule, and the named methods the evaluation
//! tables compare (`--method`), each a set of these switches over the same trainer.
//!
//! | method | deformation | motion term | representation | scene motion |
//! |---|---|---|---|---|
//! | 3dgs | off | — | — | — |
//! | deformable-3dgs | on | — | — | — |
//! | motiongs | on | α | Gaussian flow | indirect |
//! | dispflow | on | α | displacement flow | direct |

use serde::{Deserialize, Serialize};

use super::config::{DeformMode, MotionFlow, MotionOrder, TrainConfig};

/// What the motion term compares with the scene motion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionRepresentation {
    /// DispFlow-GS: the α-blended 3D displacement δ = dx(t2) − dx(t1), compared by
    /// normalised magnitude.
    #[default]
    Displacement,
    /// GaussianFlow / MotionGS: the α-blended 2D motion of the projected Gaussians between t1
    /// and t2 under the frame's view, compared as vectors (L1).
    GaussianFlow,
}

/// Which scene motion supervises the term.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SceneMotionKind {
    /// Flow between the photo and the intermediate render at the same view (the method's
    /// decomposition: camera motion never enters the flow).
    #[default]
    Direct,
    /// MotionGS: flow photo a → photo b minus the camera flow of the rendered depth.
    Indirect,
    /// The raw flow photo a → photo b, camera motion included (the paper's "DF without MD").
    None,
}

/// The motion weight's schedule (the paper's TS).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionSchedule {
    /// On from `motion_start`, α_t ramping linearly from 0.1·α to α.
    #[default]
    Ramp,
    /// The full α from the end of the deformation warm-up.
    Off,
}

/// A named method: a preset of the switches above (applied before explicit flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Static 3D Gaussian splatting: no deformation, no motion term.
    #[value(name = "3dgs")]
    #[serde(rename = "3dgs")]
    Gs3d,
    /// Deformable-3DGS: the deformation MLP, photometric loss only.
    #[value(name = "deformable-3dgs")]
    #[serde(rename = "deformable-3dgs")]
    Deformable3dgs,
    /// MotionGS: Gaussian flow supervised with indirect scene motion.
    Motiongs,
    /// DispFlow-GS: displacement flow supervised with direct scene motion (the method).
    Dispflow,
}

impl Method {
    /// Sets the switches of this method on `c` (the motion weight α keeps `c`'s value, or the
    /// paper's 0.1 where `c` had the term off).
    pub fn apply(self, c: &mut TrainConfig) {
        let alpha = if c.motion_weight > 0.0 {
            c.motion_weight
        } else {
            0.1
        };
        match self {
            Method::Gs3d => {
                c.deform = DeformMode::Off;
                c.motion_weight = 0.0;
            }
            Method::Deformable3dgs => {
                c.deform = DeformMode::On;
                c.motion_weight = 0.0;
            }
            Method::Motiongs | Method::Dispflow => {
                let gf = self == Method::Motiongs;
                c.deform = DeformMode::On;
                c.motion_weight = alpha;
                c.motion_order = MotionOrder::Direct;
                c.motion_representation = if gf {
                    MotionRepresentation::GaussianFlow
                } else {
                    MotionRepresentation::Displacement
                };
                c.scene_motion.kind = if gf {
                    SceneMotionKind::Indirect
                } else {
                    SceneMotionKind::Direct
                };
            }
        }
    }
}

/// The paper's row name for a configuration (its Tabs. 1–5).
pub fn row_name(c: &TrainConfig) -> String {
    if c.deform == DeformMode::Off {
        return "3DGS".into();
    }
    if c.motion_weight <= 0.0 {
        return "Deformable 3DGS".into();
    }
    let rep = match c.motion_representation {
        MotionRepresentation::Displacement => "Displacement Flow",
        MotionRepresentation::GaussianFlow => "Gaussian Flow",
    };
    let scene = match c.scene_motion.kind {
        SceneMotionKind::Direct => "Direct Scene Motion",
        SceneMotionKind::Indirect => "Indirect Scene Motion",
        SceneMotionKind::None => "Pair Flow (no decomposition)",
    };
    let mut name = format!("{rep} + {scene}");
    match (c.motion_representation, c.scene_motion.kind) {
        (MotionRepresentation::GaussianFlow, SceneMotionKind::Indirect) => {
            name.push_str(" (MotionGS)")
        }
        (MotionRepresentation::Displacement, SceneMotionKind::Direct) => {
            name.push_str(" (DispFlow-GS)")
        }
        _ => {}
    }
    let mut notes = Vec::new();
    if c.motion_order == MotionOrder::Reverse {
        notes.push("reverse order");
    }
    if c.motion_schedule == MotionSchedule::Off {
        notes.push("w/o TS");
    }
    if c.scene_motion.mask_px > 0.0 {
        notes.push("motion mask");
    }
    if c.motion_flow == MotionFlow::Oracle {
        notes.push("oracle flow");
    }
    if !notes.is_empty() {
        name.push_str(&format!(", {}", notes.join(", ")));
    }
    name
}

/// The combinations the trainer refuses (the motion term is on), by config field.
pub fn validate(c: &TrainConfig) -> std::result::Result<(), String> {
    let bad = |field: &str, found: &str, want: &str| {
        Err(format!("config field {field} = {found}: expected {want}"))
    };
    let gf = c.motion_representation == MotionRepresentation::GaussianFlow;
    let kind = c.scene_motion.kind;
    if gf && c.motion_order == MotionOrder::Reverse {
        return bad(
            "motion_representation",
            "\"gaussian-flow\" with motion_order = \"reverse\"",
            "motion_order = \"direct\" (Gaussian flow is the motion under the frame's view)",
        );
    }
    if kind != SceneMotionKind::Direct {
        let name = format!("\"{}\"", kind_name(kind));
        if c.motion_order == MotionOrder::Reverse {
            return bad(
                "scene_motion.kind",
                &format!("{name} with motion_order = \"reverse\""),
                "motion_order = \"direct\" (the order names the intermediate render of the direct scene motion)",
            );
        }
        if c.motion_flow == MotionFlow::Oracle {
            return bad(
                "scene_motion.kind",
                &format!("{name} with motion_flow = \"oracle\""),
                "scene_motion.kind = \"direct\" (the oracle is the frame's own scene flow)",
            );
        }
        if c.scene_motion.residual {
            return bad(
                "scene_motion.residual",
                &format!("true with scene_motion.kind = {name}"),
                "false (the residual corrects the flow to the intermediate render)",
            );
        }
    }
    Ok(())
}

pub fn kind_name(k: SceneMotionKind) -> &'static str {
    match k {
        SceneMotionKind::Direct => "direct",
        SceneMotionKind::Indirect => "indirect",
        SceneMotionKind::None => "none",
    }
}
