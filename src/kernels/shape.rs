//! Kernel families that come in a GPU shape and a CPU shape (lavapipe runs each SIMD lane's
//! barriers, shared arrays and atomics as loops, so a kernel shaped for a warp can cost it 5–25×
//! one shaped for a core). Every family picks its shape the same way: an environment variable
//! when set (benches, tests, `dispflow-vk devices`), else the device's kind.

use crate::vk::DeviceInfo;

/// One family's shapes. Both shapes compute the same outputs (up to float summation order),
/// and the family's tests run both against its CPU twin.
pub trait DeviceShape: Copy + Sized + 'static {
    /// The variable that overrides the choice, e.g. `DISPFLOW_LOSS_BLUR`.
    const ENV: &'static str;
    /// Every shape, in the order `name` lists them in messages.
    const ALL: &'static [Self];
    /// The shape CPU devices run.
    const CPU: Self;
    /// The shape every other device runs.
    const GPU: Self;
    /// The shape's name as `ENV` spells it.
    fn name(self) -> &'static str;

    /// The shape `info`'s device runs ([`for_device`]).
    fn for_device(info: &DeviceInfo) -> Self {
        for_device(info)
    }
}

/// `S`'s shape for `info`: `S::ENV`'s value when it names one, else by the device's kind.
/// An unknown value is reported on stderr (a typo must not pass as a measurement of the
/// shape it meant) and the device's choice stands.
pub fn for_device<S: DeviceShape>(info: &DeviceInfo) -> S {
    let var = std::env::var(S::ENV).ok();
    choose(var.as_deref(), info.kind == "CPU").unwrap_or_else(|(by_kind, msg)| {
        eprintln!("warning: {msg}");
        by_kind
    })
}

/// The shape `var` names, else the device kind's; `Err` carries that fallback and why.
fn choose<S: DeviceShape>(var: Option<&str>, cpu: bool) -> Result<S, (S, String)> {
    let by_kind = if cpu { S::CPU } else { S::GPU };
    let Some(v) = var else {
        return Ok(by_kind);
    };
    match S::ALL.iter().find(|s| s.name() == v) {
        Some(s) => Ok(*s),
        None => {
            let names: Vec<&str> = S::ALL.iter().map(|s| s.name()).collect();
            let msg = format!(
                "{}={v} is not one of {}; using the device's choice, {}",
                S::ENV,
                names.join(", "),
                by_kind.name()
            );
            Err((by_kind, msg))
        }
    }
}

/// How kernels with a texel variant reach their per-element arrays (`DISPFLOW_ACCESS`):
/// storage buffers (GPUs: coalesced loads) or storage texel buffers (CPU devices: llvmpipe 22.3
/// runs a storage-buffer access at per-lane addresses as a loop over the lanes, an image load
/// as one gather; glsl/include/access.glsl). Both read and write the same floats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Buffer,
    Texel,
}

impl DeviceShape for Access {
    const ENV: &'static str = "DISPFLOW_ACCESS";
    const ALL: &'static [Self] = &[Access::Buffer, Access::Texel];
    const CPU: Self = Access::Texel;
    const GPU: Self = Access::Buffer;
    fn name(self) -> &'static str {
        match self {
            Access::Buffer => "buffer",
            Access::Texel => "texel",
        }
    }
}

impl Access {
    /// `buffer`'s shader in this shape, `texel` its texel-buffer twin.
    pub fn pick(
        self,
        buffer: &'static crate::shaders::ShaderInfo,
        texel: &'static crate::shaders::ShaderInfo,
    ) -> &'static crate::shaders::ShaderInfo {
        match self {
            Access::Buffer => buffer,
            Access::Texel => texel,
        }
    }
}

/// What `info`'s device runs in every shaped family: (family, shape, the variable that
/// overrides it), for `dispflow-vk devices`.
pub fn device_choices(info: &DeviceInfo) -> Vec<(&'static str, &'static str, &'static str)> {
    fn row<S: DeviceShape>(
        what: &'static str,
        info: &DeviceInfo,
    ) -> (&'static str, &'static str, &'static str) {
        (what, S::for_device(info).name(), S::ENV)
    }
    use super::{binning::Binning, loss::BlurShape, mlp_rows::MlpKernels, motion::NormMagShape};
    use super::{nodes, nodes::GatherShape, radix_sort, raster};
    vec![
        row::<MlpKernels>("MLP", info),
        row::<raster::BlendFwdVariant>("blend forward", info),
        row::<raster::BlendBwdVariant>("blend backward", info),
        row::<raster::SplatExtent>("splat extent", info),
        row::<Binning>("tile binning", info),
        row::<GatherShape>("node gather", info),
        row::<nodes::SlotLoop>("node blend slots", info),
        row::<BlurShape>("loss blur", info),
        row::<NormMagShape>("motion magnitude", info),
        row::<radix_sort::SortShape>("radix sort", info),
        row::<Access>("array access", info),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::radix_sort::SortShape;

    #[test]
    fn a_named_shape_wins_the_kind_decides_otherwise_and_a_typo_is_reported() {
        assert_eq!(choose::<SortShape>(None, true), Ok(SortShape::Serial));
        assert_eq!(choose::<SortShape>(None, false), Ok(SortShape::Block));
        assert_eq!(
            choose::<SortShape>(Some("block"), true),
            Ok(SortShape::Block)
        );
        assert_eq!(
            choose::<SortShape>(Some("serial"), false),
            Ok(SortShape::Serial)
        );
        let (fallback, msg) = choose::<SortShape>(Some("serail"), true).unwrap_err();
        assert_eq!(fallback, SortShape::Serial);
        assert!(
            msg.contains("DISPFLOW_SORT=serail") && msg.contains("block, serial"),
            "{msg}"
        );
    }
}
