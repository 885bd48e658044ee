//! Model state: canonical Gaussians and the deformation network.

pub mod gaussians;
