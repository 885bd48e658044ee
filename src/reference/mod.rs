//! CPU twins of the GPU stages: same names, same inputs in binding order, plain loops.
//! They define what the kernels must compute; tests compare the two on identical inputs.

pub mod adam;
pub mod check;
pub mod deform;
pub mod densify;
pub mod dispflow;
pub mod flow;
pub mod gflow;
pub mod loss;
pub mod lpips;
pub mod metrics;
pub mod mlp;
pub mod motion;
pub mod nodes;
pub mod radix_sort;
pub mod raster;
pub mod scan;
pub mod sh;
pub mod sparse;
pub mod step;
pub mod temporal;
