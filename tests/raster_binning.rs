//! The two binnings (`Binning::Radix`: (tile | depth) keys per intersection, radix-sorted;
//! `Binning::DepthFirst`: the Gaussians sorted by depth, the keys emitted in that order, then
//! sorted by their tile bits only) write the same per-tile ranges and the same Gaussian-id
//! list, so every image and every gradient is bit for bit the same: on scenes with equal depths
//! (exact duplicates and shared depth planes), Gaussians outside the image and behind the
//! camera, Gaussians without a box (fainter than 1/255), large Gaussians over many tiles, tall
//! and wide grids, one tile, no Gaussian at all, and 20 000 Gaussians over 668 212
//! intersections; with both splat extents. Both match the binning's CPU twin
//! (`reference::raster::bin`, whose depth-first route builds the list stage by stage).
//!
//! The lists and the forward outputs carry no float atomics and are compared at any lavapipe
//! thread count; gradients are float-atomic sums, so that comparison re-runs itself with
//! serial lavapipe (`testing::LP_SERIAL`).

mod raster_common;

use dispflow_vk::kernels::raster::{
    Binning, Camera, RasterBuffers, Rasterizer, RenderOpts, SplatExtent,
};
use dispflow_vk::testing::{self, Noise, TestGpu};
use raster_common::*;

const TEST_GRADS: &str = "binnings_give_the_same_gradients";

/// `random_scene` with: groups of Gaussians on three shared depth planes and exact duplicates
/// (ties in depth, broken by index), some far outside the image or behind the camera, some
/// without a box (logit −30) or faint, and a few large ones over many tiles.
fn tie_scene(seed: u64, n: usize, k: u32) -> Scene {
    let mut s = random_scene(seed, n, 1, k);
    let mut r = Noise::new(seed ^ 0xb1e5);
    let planes = [2.5f32, 3.0, 4.25];
    for i in 0..n {
        match i % 10 {
            // Shared depth planes: with the identity camera, depth = z exactly.
            0..=2 => s.means[i][2] = planes[i % 3],
            // An exact duplicate of an earlier Gaussian (same depth, same tiles).
            3 if i >= 10 => {
                let j = i - 7;
                s.means[i] = s.means[j];
                s.scales[i] = s.scales[j];
                s.quats[i] = s.quats[j];
            }
            4 => s.logits[i] = -30.0,
            5 => s.logits[i] = r.uniform(-7.0, -5.0),
            6 if i % 20 == 6 => s.means[i][0] = 20.0 * s.means[i][2],
            6 => s.means[i][2] = -1.0,
            _ => {}
        }
    }
    for i in (0..n).step_by(37) {
        s.scales[i] = [r.uniform(0.5, 1.5), r.uniform(0.5, 1.5), 0.3];
    }
    s
}

fn same_bits(what: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    if let Some(i) = (0..got.len()).find(|&i| got[i].to_bits() != want[i].to_bits()) {
        panic!(
            "{what}: element {i} is {} depth-first, {} radix",
            got[i], want[i]
        );
    }
}

/// (seed, Gaussians, width, height, feature channels).
const CASES: [(u64, usize, u32, u32, u32); 7] = [
    (1, 500, 64, 48, 0),
    (2, 900, 300, 260, 3),
    (3, 400, 40, 500, 6),
    (4, 300, 16, 16, 0),
    (5, 700, 517, 33, 2),
    (6, 0, 64, 48, 0),
    // Past 65 535 loop iterations for any one serial walk over all Gaussians (lavapipe stops
    // a compiled loop there: a first, per-band scatter lost entries silently on this scene).
    (7, 20_000, 256, 256, 0),
];

fn render_binned(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    b: Binning,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
) -> (RasterBuffers, Rendered) {
    rast.set_binning(b);
    render(gpu, rast, cam, up, opts)
}

/// Runs `check` on each of `cases` × splat extent.
fn each_case(
    cases: &[(u64, usize, u32, u32, u32)],
    mut check: impl FnMut(&str, &TestGpu, &mut Rasterizer, &Scene, &Camera, &Uploaded, &RenderOpts),
) {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    for &(seed, n, w, h, k) in cases {
        let scene = tie_scene(seed, n, k);
        let cam = camera(w, h);
        let up = Uploaded::new(&gpu, &scene);
        let opts = RenderOpts {
            background: [0.1, 0.2, 0.3],
            alpha_max: 0.99,
            abs_grad: true,
            detach_feature_weights: k > 0,
        };
        for e in SplatExtent::ALL {
            rast.set_splat_extent(e);
            let ctx = format!("seed {seed}, n {n}, {w}x{h}, k {k}, {}", e.name());
            check(&ctx, &gpu, &mut rast, &scene, &cam, &up, &opts);
        }
    }
}

#[test]
fn depth_first_is_the_cpu_default() {
    let gpu = testing::gpu();
    let by_kind = if gpu.info.kind == "CPU" {
        Binning::DepthFirst
    } else {
        Binning::Radix
    };
    // An override names the choice instead (an unknown name falls back to the kind's).
    let want = std::env::var("DISPFLOW_BINNING")
        .ok()
        .and_then(|v| Binning::ALL.into_iter().find(|b| b.name() == v))
        .unwrap_or(by_kind);
    assert_eq!(Rasterizer::new(&gpu).unwrap().binning(), want);
}

#[test]
fn binnings_give_the_same_lists_and_images() {
    each_case(&CASES, |ctx, gpu, rast, scene, cam, up, opts| {
        let (br, fr) = render_binned(gpu, rast, Binning::Radix, cam, up, opts);
        let (bd, fd) = render_binned(gpu, rast, Binning::DepthFirst, cam, up, opts);
        let m = br.intersections(gpu).unwrap();
        assert_eq!(bd.intersections(gpu).unwrap(), m, "{ctx}: intersections");
        let area: u32 = (bd.tile_rects(gpu, up.n).unwrap().iter())
            .map(|r| (r[2] - r[0]) * (r[3] - r[1]))
            .sum();
        assert_eq!(
            m, area,
            "{ctx}: intersections against the rectangles' areas"
        );
        let ranges = br.tile_ranges(gpu).unwrap();
        assert_eq!(bd.tile_ranges(gpu).unwrap(), ranges, "{ctx}: tile ranges");
        let ids = br.intersection_ids(gpu).unwrap();
        let got = bd.intersection_ids(gpu).unwrap();
        if let Some(j) = (0..ids.len()).find(|&j| got[j] != ids[j]) {
            panic!(
                "{ctx}: intersection {j} of {m} is Gaussian {} depth-first, {} radix",
                got[j], ids[j]
            );
        }
        assert_eq!(got.len(), ids.len(), "{ctx}: id list length");
        // The scene tests ties: adjacent entries of one tile at one depth, in index order.
        let ties = ranges
            .iter()
            .flat_map(|r| (r[0] + 1..r[1]).map(|j| (ids[j as usize - 1], ids[j as usize])))
            .filter(|&(a, b)| scene.means[a as usize][2] == scene.means[b as usize][2])
            .inspect(|&(a, b)| assert!(a < b, "{ctx}: tie {a}, {b} out of index order"))
            .count();
        assert!(
            scene.len() == 0 || ties > 10,
            "{ctx}: only {ties} ties in {m} intersections: the scene tests little"
        );
        assert!(
            scene.len() > 0 || m == 0,
            "{ctx}: an empty scene binned {m}"
        );
        println!("{ctx}: {m} intersections, {ties} ties");
        let flat = |r: &Rendered| r.rgba.as_flattened().to_vec();
        same_bits(&format!("{ctx}: rgba"), &flat(&fd), &flat(&fr));
        same_bits(&format!("{ctx}: depth"), &fd.depth, &fr.depth);
        same_bits(&format!("{ctx}: final T"), &fd.final_t, &fr.final_t);
        same_bits(&format!("{ctx}: features"), &fd.features, &fr.features);
        assert_eq!(fd.n_contrib, fr.n_contrib, "{ctx}: contributors");
    });
}

/// Both binnings against the binning's CPU twin (`reference::raster::bin`), fed the GPU's own
/// splat depths and tile rectangles: the same id list and ranges, and the twin's depth-first
/// route, stage by stage, gives its radix route's list.
#[test]
fn binnings_match_the_twin() {
    use dispflow_vk::kernels::raster::SPLAT_STRIDE;
    use dispflow_vk::reference::raster::bin;
    each_case(&CASES, |ctx, gpu, rast, _scene, cam, up, opts| {
        let (tx, ty) = cam.tiles();
        for b in Binning::ALL {
            let (buf, _) = render_binned(gpu, rast, b, cam, up, opts);
            let n = up.n as u64;
            let splats: Vec<[f32; 4]> = gpu
                .read(buf.splats.elems::<[f32; 4]>(0, n * SPLAT_STRIDE))
                .unwrap();
            let depth: Vec<u32> = (0..n as usize)
                .map(|i| splats[i * SPLAT_STRIDE as usize][2].to_bits())
                .collect();
            let rects = buf.tile_rects(gpu, up.n).unwrap();
            let want = bin::bin(&depth, &rects, tx, ty);
            let name = b.name();
            assert_eq!(
                buf.tile_ranges(gpu).unwrap(),
                want.ranges,
                "{ctx}, {name}: ranges"
            );
            let got = buf.intersection_ids(gpu).unwrap();
            assert_eq!(got.len(), want.ids.len(), "{ctx}, {name}: list length");
            if let Some(j) = (0..got.len()).find(|&j| got[j] != want.ids[j]) {
                panic!(
                    "{ctx}, {name}: intersection {j} is Gaussian {} on the GPU, {} in the twin",
                    got[j], want.ids[j]
                );
            }
            let d = bin::bin_depth_first(&depth, &rects, tx, ty);
            assert!(
                d.ids == want.ids && d.ranges == want.ranges,
                "{ctx}: twin routes"
            );
        }
    });
}

#[test]
fn binnings_give_the_same_gradients() {
    let Some(gpu) = rerun_single_threaded(testing::gpu(), TEST_GRADS) else {
        return;
    };
    drop(gpu);
    // Not the 20 000-Gaussian scene: its lists are compared above, and its single-threaded
    // backward would double the test's time.
    each_case(&CASES[..6], |ctx, gpu, rast, _scene, cam, up, opts| {
        let (br, _) = render_binned(gpu, rast, Binning::Radix, cam, up, opts);
        let (bd, _) = render_binned(gpu, rast, Binning::DepthFirst, cam, up, opts);
        let u = upstream(
            7,
            (cam.width * cam.height) as usize,
            up.feature_dims as usize,
        );
        // The backward reads what the forward binned; run it under each binning choice.
        rast.set_binning(Binning::Radix);
        let gr = backward_each(gpu, rast, &br, cam, up, opts, &u);
        rast.set_binning(Binning::DepthFirst);
        let gd = backward_each(gpu, rast, &bd, cam, up, opts, &u);
        for ((bv, d), (_, r)) in gd.into_iter().zip(gr) {
            let c = format!("{ctx}, blend_bwd {}", bv.name());
            same_bits(&format!("{c}: grad2d"), &d.grad2d, &r.grad2d);
            same_bits(&format!("{c}: d features"), &d.d_features, &r.d_features);
            same_bits(&format!("{c}: d means"), &d.d_means, &r.d_means);
            same_bits(&format!("{c}: d scales"), &d.d_scales, &r.d_scales);
            same_bits(&format!("{c}: d quats"), &d.d_quats, &r.d_quats);
            same_bits(&format!("{c}: d logits"), &d.d_logits, &r.d_logits);
            same_bits(&format!("{c}: d sh"), &d.d_sh, &r.d_sh);
        }
    });
}

dispflow_vk::subgroup_reruns!();
