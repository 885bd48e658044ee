//! Model state: canonical Gaussians and the deformation network (configuration, parameter
//! layout, initialisation, optimiser settings) and their GPU state (`state`).

pub mod deform;
pub mod dynamic;
pub mod gaussians;
pub mod nodes;
pub mod optim;
pub mod rows;
pub mod state;
