//! The CPU report module: colour maps, bitmap text, labelled strips, line plots, Markdown
//! tables and PNG writing. Pixel checks use colours and luminance, not golden images, so the
//! tests survive layout tweaks.

use dispflow_vk::report::{
    draw_text, error_map, fmt_metric, heatmap, labelled_strip, mask_image, rgb_image, save_png,
    stacked, text_width, Plot, Series, Table, ERROR_FULL_SCALE, PALETTE,
};
use dispflow_vk::Error;
use image::{Rgb, RgbImage};

fn luminance(p: &Rgb<u8>) -> f32 {
    0.2126 * p[0] as f32 + 0.7152 * p[1] as f32 + 0.0722 * p[2] as f32
}

fn count_color(img: &RgbImage, c: [u8; 3]) -> usize {
    img.pixels().filter(|p| p.0 == c).count()
}

fn invalid_message(e: Error) -> String {
    match e {
        Error::Invalid(m) => m,
        other => panic!("expected Error::Invalid, got {other:?}"),
    }
}

// ---- colour maps ----

#[test]
fn heatmap_size_and_brightness_order() {
    let (w, h) = (4, 3);
    let mut v = vec![0.5f32; 12];
    v[0] = 0.0;
    v[1] = 1.0;
    v[2] = f32::NAN;
    v[3] = 7.0; // clamped to 1
    v[4] = -3.0; // clamped to 0
    v[5] = f32::INFINITY;
    let img = heatmap(&v, w, h).unwrap();
    assert_eq!(img.dimensions(), (w, h));
    let dark = luminance(img.get_pixel(0, 0));
    let bright = luminance(img.get_pixel(1, 0));
    assert!(dark < 20.0, "0 should be near black, luminance {dark}");
    assert!(bright > 200.0, "1 should be bright, luminance {bright}");
    assert_eq!(img.get_pixel(3, 0), img.get_pixel(1, 0));
    assert_eq!(img.get_pixel(0, 1), img.get_pixel(0, 0));
    assert_eq!(img.get_pixel(1, 1), img.get_pixel(1, 0));
    let mid = luminance(img.get_pixel(2, 1));
    assert!(dark < mid && mid < bright);
    // NaN is a neutral grey, unlike any map colour.
    let nan = img.get_pixel(2, 0);
    assert!(nan[0] == nan[1] && nan[1] == nan[2], "{nan:?}");
}

#[test]
fn colour_maps_reject_size_mismatch() {
    assert!(heatmap(&[0.0; 5], 2, 3).is_err());
    assert!(mask_image(&[0; 7], 2, 3).is_err());
    assert!(rgb_image(&[[0.0; 4]; 2], 2, 3).is_err());
    let six = [[0.0f32; 4]; 6];
    assert!(error_map(&six, &six[..5], 2, 3).is_err());
    assert!(error_map(&six[..5], &six, 2, 3).is_err());
    let msg = invalid_message(heatmap(&[0.0; 5], 2, 3).unwrap_err());
    assert!(msg.contains("2x3"), "{msg}");
    // Zero-sized images are valid, just empty.
    assert_eq!(heatmap(&[], 0, 0).unwrap().dimensions(), (0, 0));
}

#[test]
fn mask_is_black_and_white() {
    let img = mask_image(&[0, 1, 255, 0], 2, 2).unwrap();
    assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
    assert_eq!(img.get_pixel(1, 0).0, [255, 255, 255]);
    assert_eq!(img.get_pixel(0, 1).0, [255, 255, 255]);
    assert_eq!(img.get_pixel(1, 1).0, [0, 0, 0]);
}

#[test]
fn error_map_dark_where_equal_bright_where_far() {
    let gt = vec![[0.2f32, 0.5, 0.8, 1.0]; 4];
    let mut render = gt.clone();
    // Pixel 1: alpha differs only, which is ignored.
    render[1][3] = 0.0;
    // Pixel 2: every channel off by exactly the full-scale error.
    for v in &mut render[2][..3] {
        *v += ERROR_FULL_SCALE;
    }
    // Pixel 3: far beyond full scale.
    render[3] = [1.0, 0.0, 0.0, 1.0];
    let img = error_map(&render, &gt, 2, 2).unwrap();
    assert_eq!(img.dimensions(), (2, 2));
    assert!(luminance(img.get_pixel(0, 0)) < 20.0);
    assert!(luminance(img.get_pixel(1, 0)) < 20.0);
    assert!(luminance(img.get_pixel(0, 1)) > 200.0);
    assert!(luminance(img.get_pixel(1, 1)) > 200.0);
}

#[test]
fn rgb_image_clamps_and_rounds() {
    let px = [
        [0.0, 0.5, 1.0, 0.3],
        [-1.0, 2.0, f32::NAN, 1.0],
        [0.2, 0.998, 0.001, 1.0],
    ];
    let img = rgb_image(&px, 3, 1).unwrap();
    assert_eq!(img.get_pixel(0, 0).0, [0, 128, 255]);
    assert_eq!(img.get_pixel(1, 0).0, [0, 255, 0]);
    assert_eq!(img.get_pixel(2, 0).0, [51, 254, 0]);
}

// ---- text ----

#[test]
fn text_width_counts_characters() {
    assert_eq!(text_width("", 1), 0);
    assert_eq!(text_width("abc", 1), 24);
    assert_eq!(text_width("abc", 2), 48);
    assert_eq!(text_width("é?", 1), 16);
}

#[test]
fn draw_text_changes_pixels_in_range() {
    let mut img = RgbImage::new(40, 12);
    draw_text(&mut img, 2, 2, "Hi", [255, 0, 0], 1);
    let lit = count_color(&img, [255, 0, 0]);
    assert!(lit > 10, "{lit} pixels lit");
    // All ink inside the two glyph cells.
    for (x, y, p) in img.enumerate_pixels() {
        if p.0 != [0, 0, 0] {
            assert!((2..18).contains(&x) && (2..10).contains(&y), "({x},{y})");
        }
    }
    // Scale 2 lights four times the pixels of scale 1.
    let mut big = RgbImage::new(40, 20);
    draw_text(&mut big, 2, 2, "Hi", [255, 0, 0], 2);
    assert_eq!(count_color(&big, [255, 0, 0]), 4 * lit);
    // Non-ASCII is drawn as '?', not skipped.
    let mut a = RgbImage::new(8, 8);
    let mut b = RgbImage::new(8, 8);
    draw_text(&mut a, 0, 0, "é", [255; 3], 1);
    draw_text(&mut b, 0, 0, "?", [255; 3], 1);
    assert_eq!(a, b);
    assert!(count_color(&a, [255; 3]) > 0);
}

#[test]
fn draw_text_clips_anywhere() {
    let mut img = RgbImage::new(20, 10);
    let coords = [
        (-5, -3),
        (-1000, 5),
        (15, 7),
        (19, 9),
        (20, 10),
        (i32::MAX, i32::MAX),
        (i32::MIN, i32::MIN),
        (i32::MAX, 0),
        (0, i32::MIN),
    ];
    for (x, y) in coords {
        for scale in [0, 1, 3] {
            draw_text(&mut img, x, y, "clip me |é", [9, 9, 9], scale);
        }
    }
    // Partly visible text still leaves ink; a huge scale is clipped to the image.
    let mut img = RgbImage::new(20, 10);
    draw_text(&mut img, -4, -4, "W", [255; 3], 1);
    assert!(count_color(&img, [255; 3]) > 0);
    draw_text(&mut img, -1_000_000, -1_000_000, "M", [1, 2, 3], 1_000_000);
    let mut empty = RgbImage::new(0, 0);
    draw_text(&mut empty, 0, 0, "x", [255; 3], 1);
}

// ---- strips and PNG output ----

fn solid(w: u32, h: u32, c: [u8; 3]) -> RgbImage {
    RgbImage::from_pixel(w, h, Rgb(c))
}

#[test]
fn strip_layout() {
    let a = solid(30, 20, [200, 0, 0]);
    let b = solid(50, 20, [0, 200, 0]);
    let c = solid(10, 20, [0, 0, 200]);
    let s = labelled_strip(&[("render", &a), ("ground truth", &b), ("err", &c)]).unwrap();
    assert_eq!(s.dimensions(), (30 + 2 + 50 + 2 + 10, 20 + 12));
    // Panels sit under the label band, a 2-px gap apart.
    assert_eq!(s.get_pixel(0, 12).0, [200, 0, 0]);
    assert_eq!(s.get_pixel(29, 31).0, [200, 0, 0]);
    assert_ne!(s.get_pixel(30, 20).0, [200, 0, 0]);
    assert_ne!(s.get_pixel(31, 20).0, [0, 200, 0]);
    assert_eq!(s.get_pixel(32, 12).0, [0, 200, 0]);
    assert_eq!(s.get_pixel(84, 12).0, [0, 0, 200]);
    // Labels put light ink into the band above each panel.
    let band_ink = |x0: u32, x1: u32| {
        (x0..x1)
            .flat_map(|x| (0..12).map(move |y| (x, y)))
            .filter(|&(x, y)| luminance(s.get_pixel(x, y)) > 128.0)
            .count()
    };
    assert!(band_ink(0, 30) > 0);
    assert!(band_ink(32, 82) > 0);
    assert!(band_ink(84, 94) > 0);
}

#[test]
fn strip_errors() {
    let a = solid(10, 20, [1; 3]);
    let b = solid(10, 21, [1; 3]);
    let msg = invalid_message(labelled_strip(&[("ok", &a), ("too tall", &b)]).unwrap_err());
    assert!(msg.contains("too tall"), "{msg}");
    assert!(labelled_strip(&[]).is_err());
}

#[test]
fn save_png_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nested/deeper/strip.png");
    let mut img = solid(7, 5, [10, 20, 30]);
    img.put_pixel(3, 2, Rgb([250, 1, 2]));
    save_png(&img, &path).unwrap();
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back.dimensions(), (7, 5));
    assert_eq!(back, img);
    // Overwriting works and no temporary file is left anywhere.
    save_png(&solid(3, 4, [0; 3]), &path).unwrap();
    assert_eq!(image::open(&path).unwrap().to_rgb8().dimensions(), (3, 4));
    let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names, ["strip.png"]);
}

#[test]
fn save_png_error_names_path() {
    let dir = tempfile::tempdir().unwrap();
    // A file where the parent directory should be.
    let blocker = dir.path().join("blocker");
    std::fs::write(&blocker, b"x").unwrap();
    let path = blocker.join("out.png");
    match save_png(&solid(2, 2, [0; 3]), &path) {
        Err(Error::Io { path: p, .. }) => assert!(p.contains("blocker"), "{p}"),
        other => panic!("expected Error::Io, got {other:?}"),
    }
}

// ---- plots ----

fn series(label: &str, color: [u8; 3], points: Vec<(f64, f64)>) -> Series {
    Series {
        label: label.into(),
        points,
        color,
    }
}

fn plot(series: Vec<Series>, width: u32, height: u32) -> Plot {
    Plot {
        title: "training loss".into(),
        x_label: "iteration".into(),
        y_label: "loss".into(),
        series,
        width,
        height,
    }
}

fn curve(n: usize, f: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    (0..n).map(|i| (i as f64 * 10.0, f(i as f64))).collect()
}

#[test]
fn palette_colours_are_distinct() {
    for (i, a) in PALETTE.iter().enumerate() {
        for b in &PALETTE[i + 1..] {
            assert_ne!(a, b);
        }
    }
}

#[test]
fn plot_draws_every_series() {
    // Unlabelled series: no legend, so every series-coloured pixel is part of a curve.
    let p = plot(
        vec![
            series("", PALETTE[0], curve(60, |t| (-t / 20.0).exp())),
            series("", PALETTE[1], curve(60, |t| 0.5 + 0.3 * (t / 5.0).sin())),
            series("", PALETTE[2], curve(60, |t| t / 100.0)),
        ],
        400,
        300,
    );
    let img = p.render().unwrap();
    assert_eq!(img.dimensions(), (400, 300));
    let bare: Vec<usize> = PALETTE[..3].iter().map(|&c| count_color(&img, c)).collect();
    for (i, n) in bare.iter().enumerate() {
        assert!(*n >= 100, "series {i}: only {n} pixels");
    }
    // With labels the legend adds ink in each colour.
    let mut labelled = p.clone();
    for (s, l) in labelled.series.iter_mut().zip(["psnr", "ssim", "lpips"]) {
        s.label = l.into();
    }
    let img = labelled.render().unwrap();
    for (i, &c) in PALETTE[..3].iter().enumerate() {
        let n = count_color(&img, c);
        assert!(n > 30, "series {i}: {n} pixels with legend");
    }
    // Dark text (title, ticks, labels) is present.
    assert!(img.pixels().filter(|p| luminance(p) < 60.0).count() > 200);
}

#[test]
fn plot_survives_non_finite_points() {
    let pts = vec![
        (0.0, 1.0),
        (1.0, f64::NAN),
        (2.0, 2.0),
        (3.0, 3.0),
        (f64::INFINITY, 1.0),
        (4.0, f64::NEG_INFINITY),
        (5.0, 0.5),
        (f64::NAN, f64::NAN),
    ];
    let img = plot(vec![series("", PALETTE[3], pts)], 300, 200)
        .render()
        .unwrap();
    assert!(count_color(&img, PALETTE[3]) > 20);
}

#[test]
fn plot_handles_degenerate_ranges() {
    // Constant series: the padded range keeps the line inside the box.
    let flat = plot(vec![series("", PALETTE[0], curve(20, |_| 3.0))], 300, 200)
        .render()
        .unwrap();
    assert!(count_color(&flat, PALETTE[0]) > 100);
    let zero = plot(vec![series("", PALETTE[0], curve(20, |_| 0.0))], 300, 200)
        .render()
        .unwrap();
    assert!(count_color(&zero, PALETTE[0]) > 100);
    // One point: a dot.
    let dot = plot(vec![series("", PALETTE[1], vec![(5.0, 5.0)])], 300, 200)
        .render()
        .unwrap();
    assert!(count_color(&dot, PALETTE[1]) >= 9);
    // Extreme magnitudes must not panic.
    for pts in [
        vec![(-1e308, -1e308), (1e308, 1e308)],
        vec![(0.0, 1e-300), (1.0, 2e-300)],
        vec![(1e15, 1.0), (1e15 + 1.0, 1.0 + 1e-15)],
    ] {
        plot(vec![series("x", PALETTE[2], pts)], 200, 120)
            .render()
            .unwrap();
    }
}

#[test]
fn plot_without_data_says_so() {
    let empty = plot(vec![series("empty", PALETTE[0], vec![])], 300, 200);
    let img = empty.render().unwrap();
    assert_eq!(count_color(&img, PALETTE[0]), 0);
    // "no data" is drawn centred in the box; compare with the same plot minus the text by
    // checking that the centre region has dark ink.
    let centre_ink = (100..200)
        .flat_map(|x| (80..130).map(move |y| (x, y)))
        .filter(|&(x, y)| luminance(img.get_pixel(x, y)) < 100.0)
        .count();
    assert!(centre_ink > 20, "{centre_ink}");
    let none = plot(vec![], 300, 200).render().unwrap();
    assert_eq!(none, img);
    let all_nan = plot(
        vec![series("", PALETTE[0], vec![(f64::NAN, 1.0)])],
        300,
        200,
    );
    assert_eq!(all_nan.render().unwrap(), img);
}

#[test]
fn plot_rejects_tiny_sizes() {
    let s = vec![series("a", PALETTE[0], curve(5, |t| t))];
    assert!(plot(s.clone(), 119, 200).render().is_err());
    assert!(plot(s.clone(), 300, 79).render().is_err());
    assert!(plot(s.clone(), 0, 0).render().is_err());
    let img = plot(s, 120, 80).render().unwrap();
    assert_eq!(img.dimensions(), (120, 80));
}

#[test]
fn stacked_checks_widths() {
    let a = solid(10, 4, [1; 3]);
    let b = solid(10, 6, [2; 3]);
    let s = stacked(&[a.clone(), b.clone()]).unwrap();
    assert_eq!(s.dimensions(), (10, 10));
    assert_eq!(s.get_pixel(0, 3).0, [1; 3]);
    assert_eq!(s.get_pixel(9, 4).0, [2; 3]);
    let msg = invalid_message(stacked(&[a, solid(11, 4, [0; 3])]).unwrap_err());
    assert!(msg.contains("11"), "{msg}");
    assert!(stacked(&[]).is_err());
}

// ---- tables ----

fn sample_table() -> Table {
    Table {
        headers: vec!["scene".into(), "PSNR".into(), "mAP|motion".into()],
        rows: vec![
            vec!["as|bs".into(), fmt_metric(Some(27.4567), 2), "n/a".into()],
            vec![
                "C:\\data\\x".into(),
                fmt_metric(Some(f64::NAN), 2),
                fmt_metric(None, 3),
            ],
            vec!["".into(), "1".into(), "0.5".into()],
        ],
    }
}

#[test]
fn table_round_trip() {
    let t = sample_table();
    let md = t.to_markdown();
    assert_eq!(Table::parse_markdown(&md).unwrap(), t);
    let lines: Vec<&str> = md.lines().collect();
    assert_eq!(lines.len(), 2 + t.rows.len());
    // First column left-aligned, the others right-aligned.
    assert!(lines[1].starts_with("| ---"), "{}", lines[1]);
    assert!(!lines[1].starts_with("| :"), "{}", lines[1]);
    assert_eq!(lines[1].matches(": |").count(), 2, "{}", lines[1]);
    assert!(md.contains("as\\|bs"), "{md}");
    // Padding makes every line equally wide.
    let width = lines[0].chars().count();
    assert!(lines.iter().all(|l| l.chars().count() == width), "{md}");
}

#[test]
fn table_parse_skips_prose_and_stops_at_table_end() {
    let md = format!(
        "# Results\n\nSome prose with a | pipe in it.\n\n{}\nMore text after.\n| not | part |\n",
        sample_table().to_markdown()
    );
    assert_eq!(Table::parse_markdown(&md).unwrap(), sample_table());
    // Hand-written: alignment colons, no trailing pipes, loose spacing.
    let t = Table::parse_markdown("|a|b\n|:-|:-:\n| 1 |2\n").unwrap();
    assert_eq!(t.headers, ["a", "b"]);
    assert_eq!(t.rows, [["1", "2"]]);
}

#[test]
fn table_parse_errors_name_the_line() {
    let md = "intro\n\n| a | b |\n|---|--:|\n| 1 | 2 |\n| 3 |\n";
    let msg = invalid_message(Table::parse_markdown(md).unwrap_err());
    assert!(msg.contains("line 6"), "{msg}");
    let md = "| a | b |\n|---|\n";
    let msg = invalid_message(Table::parse_markdown(md).unwrap_err());
    assert!(msg.contains("line 2"), "{msg}");
    assert!(Table::parse_markdown("no table here\n| just | a | row |\n").is_err());
    assert!(Table::parse_markdown("").is_err());
}

#[test]
fn fmt_metric_cases() {
    assert_eq!(fmt_metric(Some(1.23456), 3), "1.235");
    assert_eq!(fmt_metric(Some(2.0), 0), "2");
    assert_eq!(fmt_metric(Some(-0.0001), 2), "0.00");
    assert_eq!(fmt_metric(Some(-0.5), 1), "-0.5");
    assert_eq!(fmt_metric(None, 2), "n/a");
    assert_eq!(fmt_metric(Some(f64::INFINITY), 2), "n/a");
    assert_eq!(fmt_metric(Some(f64::NAN), 2), "n/a");
}
