//! The transient population's room (issue 37): which pixels are wrong ([`residual`]), the ray
//! maths both spawning and tracking stand on ([`ray`]), the tracker that explains a wrong pixel
//! by a point moving at constant velocity through the temporal neighbours ([`track`]), the
//! spawn rules and what one frame spawns ([`spawn`]), and the trainer's spawn round
//! (`round`: `Trainer::spawn_transients`), and the resolution of a spawn's depth hypotheses
//! ([`resolve`]). Dependencies point down: round → spawn → track → ray, residual.

pub mod ray;
pub mod residual;
pub mod resolve;
mod round;
pub mod spawn;
pub mod track;
