//! The commands that reopen a trained run: `eval` ([`run`]: scores, tables, pictures),
//! `render` ([`render`]: camera paths, PLY sequences, GIFs; [`export`]) and `signal`
//! ([`signal`]: scene-motion quality per kept checkpoint); and `score-renders`
//! ([`reference`]: another implementation's test renders scored by the same evaluation). They sit above [`crate::train`]:
//! a run is reloaded into a [`crate::train::Trainer`] and scored by
//! [`crate::train::score::Evaluator`], the same code training's test probe runs; nothing in
//! `train` imports from here.

pub mod export;
pub mod reference;
pub mod render;
pub mod run;
pub mod signal;
