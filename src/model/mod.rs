//! Model state: canonical Gaussians and the deformation network (configuration, parameter
//! layout, initialisation, optimiser settings).

pub mod deform;
pub mod gaussians;
pub mod optim;
