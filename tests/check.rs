//! The non-finite count (`glsl/check/count_nonfinite.comp`) against its twin on identical
//! inputs: NaN (quiet, signalling, negative), ±Inf planted among finite extremes that must not
//! count (±f32::MAX, the smallest subnormal, −0), ranges that start mid-buffer and end mid-
//! workgroup, several ranges into one slot, an empty range, and a clean buffer.

use dispflow_vk::kernels::check::{NonFinite, NonFiniteCheck};
use dispflow_vk::reference::check as twin;
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

dispflow_vk::subgroup_reruns!();

/// `n` floats: noise with the finite extremes sprinkled in, and non-finite values at `bad`.
fn data(seed: u64, n: usize, bad: &[usize]) -> Vec<f32> {
    let mut r = Noise::new(seed);
    let finite = [
        f32::MAX,
        -f32::MAX,
        f32::from_bits(1),
        -0.0,
        f32::MIN_POSITIVE,
    ];
    let nonfinite = [
        f32::NAN,
        -f32::NAN,
        f32::from_bits(0x7f80_0001), // signalling NaN
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    let mut x: Vec<f32> = (0..n)
        .map(|i| match r.next_u32() % 97 {
            0 => finite[i % finite.len()],
            _ => (r.next_u32() as f32 / 4.0e9 - 0.5) * 1e3,
        })
        .collect();
    for (k, &i) in bad.iter().enumerate() {
        x[i] = nonfinite[k % nonfinite.len()];
    }
    x
}

#[test]
fn counts_match_the_twin() {
    let gpu = testing::gpu();
    let n = 300_007;
    let bad = [5, 6, 255, 256, 70_001, 70_002, 150_000, 299_999, 300_006];
    let x = data(1, n, &bad);
    let xb = gpu.buffer_from("x", &x).unwrap();
    let check = NonFiniteCheck::new(&gpu, 5).unwrap();
    // (first, count, slot): the whole buffer; a range starting mid-buffer and ending
    // mid-workgroup; two ranges into one slot; an empty range; a clean range.
    let ranges = [
        (0usize, n, 0u32),
        (6, 70_000, 1),
        (1000, 69_002, 2),
        (200_000, 100_007, 2),
        (17, 0, 3),
        (300, 60_000, 4),
    ];
    let mut rec = Recorder::new(&gpu).unwrap();
    check.reset(&mut rec);
    for &(first, count, slot) in &ranges {
        check.count(&mut rec, xb.all(), first as u32, count as u32, slot);
    }
    rec.finish().unwrap();
    let got = check.read(&gpu).unwrap();
    let mut want = vec![NonFinite::default(); 5];
    for &(first, count, slot) in &ranges {
        let t = twin::count_nonfinite(&x, first, count);
        let w = &mut want[slot as usize];
        w.count += t.count;
        w.first = match (w.first, t.first) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
    }
    assert_eq!(got, want);
    // The twin itself, by hand: every planted value is found, no finite extreme is.
    assert_eq!(
        want[0],
        NonFinite {
            count: bad.len() as u32,
            first: Some(5)
        }
    );
    assert_eq!(
        want[1],
        NonFinite {
            count: 5,
            first: Some(0)
        }
    ); // 6, 255, 256, 70_001, 70_002
    assert_eq!(want[3], NonFinite::default());
    assert_eq!(want[4], NonFinite::default());

    // A reset forgets the last counts.
    let mut rec = Recorder::new(&gpu).unwrap();
    check.reset(&mut rec);
    check.count(&mut rec, xb.all(), 300, 60_000, 0);
    rec.finish().unwrap();
    assert_eq!(check.read(&gpu).unwrap()[0], NonFinite::default());
}
