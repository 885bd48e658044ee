//! Golden image: a small fixed scene rendered to PNG and compared with the checked-in
//! `tests/golden/raster_64x48.png` (8-bit, at most 1 level of difference per channel, for
//! rounding). Regenerate deliberately with `DISPFLOW_BLESS=1 cargo test --release --test raster_golden`
//! and look at the picture before committing it.

mod raster_common;

use dispflow_vk::kernels::raster::{Rasterizer, RenderOpts};
use dispflow_vk::testing;
use raster_common::*;

fn golden_scene() -> Scene {
    let mut s = Scene {
        sh_coeffs: 4,
        sh_degree: 1,
        ..Default::default()
    };
    let colours = [
        [0.9, 0.2, 0.1],
        [0.1, 0.8, 0.2],
        [0.2, 0.3, 0.95],
        [0.95, 0.9, 0.2],
    ];
    for i in 0..12 {
        let a = i as f32 * 0.52;
        let z = 3.0 + 0.15 * i as f32;
        let q = [a.cos(), 0.3 * a.sin(), 0.0, a.sin()];
        s.push(
            [0.9 * a.cos(), 0.6 * a.sin(), z],
            [0.35, 0.08 + 0.02 * i as f32, 0.1],
            q,
            1.5 - 0.2 * i as f32,
            colours[i % 4],
        );
    }
    // A view-dependent tint on the first band, so the SH path is part of the picture.
    for i in 0..12 {
        s.sh[(i * 4 + 3) * 3] = 0.4;
    }
    s
}

#[test]
fn small_scene_matches_golden_png() {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    let cam = camera(64, 48);
    let up = Uploaded::new(&gpu, &golden_scene());
    let opts = RenderOpts {
        background: [0.05, 0.05, 0.08],
        alpha_max: 0.99,
        abs_grad: false,
        detach_feature_weights: false,
    };
    // Every blend-forward variant against the one golden image.
    for (fv, _, out) in render_each(&gpu, &mut rast, &cam, &up, &opts) {
        check_golden(fv.name(), &out);
    }
}

fn check_golden(variant: &str, out: &Rendered) {
    let img = image::RgbImage::from_fn(64, 48, |x, y| {
        let p = out.rgba[(y * 64 + x) as usize];
        image::Rgb([0, 1, 2].map(|c| (p[c].clamp(0.0, 1.0) * 255.0).round() as u8))
    });
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/raster_64x48.png");
    if std::env::var("DISPFLOW_BLESS").as_deref() == Ok("1") {
        img.save(&path).unwrap();
        eprintln!("wrote {}", path.display());
        return;
    }
    let want = image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (bless with DISPFLOW_BLESS=1)", path.display()))
        .to_rgb8();
    assert_eq!(want.dimensions(), img.dimensions());
    let worst = img
        .pixels()
        .zip(want.pixels())
        .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
        .max()
        .unwrap();
    assert!(
        worst <= 1,
        "blend_fwd {variant}: golden image differs by up to {worst} levels"
    );
    // The picture is not trivially empty: several distinct colours are present.
    let lit = img
        .pixels()
        .filter(|p| p[0] > 60 || p[1] > 60 || p[2] > 60)
        .count();
    assert!(
        lit > 64 * 48 / 5,
        "blend_fwd {variant}: only {lit} lit pixels"
    );
}

dispflow_vk::subgroup_reruns!();
