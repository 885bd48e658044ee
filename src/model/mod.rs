//! Model state: the deformation network's configuration, parameter layout and initialisation.

pub mod deform;
pub mod optim;
