//! Radix sort: GPU vs the CPU twin (a plain stable sort), for u32 and u64 keys, at sizes
//! around block edges and beyond 2^22, with adversarial key patterns and GPU-resident counts;
//! every check on both shapes of the digit passes (`SortShape`).

use dispflow_vk::kernels::radix_sort::{DeviceShape, KeyWidth, RadixSort, SortBuffers, SortShape};
use dispflow_vk::kernels::scan::Count;
use dispflow_vk::reference::radix_sort::{sort_pairs_u32, sort_pairs_u64};
use dispflow_vk::testing::{self, Noise, TestGpu};
use dispflow_vk::vk::Recorder;

/// Runs the GPU sort on `keys` (u32 or u64 words) with values 0..n; returns (keys, values).
fn gpu_sort_u32(
    gpu: &TestGpu,
    sort: &RadixSort,
    b: &SortBuffers,
    keys: &[u32],
    bits: u32,
) -> (Vec<u32>, Vec<u32>) {
    let n = keys.len() as u64;
    let vals: Vec<u32> = (0..n as u32).collect();
    for i in 0..2 {
        testing::fill_noise(gpu, &b.keys[i], 10 + i as u64);
        testing::fill_noise(gpu, &b.vals[i], 20 + i as u64);
    }
    gpu.upload(b.keys[0].all(), keys).unwrap();
    gpu.upload(b.vals[0].all(), &vals).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    let out = sort.record(&mut rec, b, Count::Host(n as u32), bits);
    rec.finish().unwrap();
    (
        gpu.read(b.keys[out].elems::<u32>(0, n)).unwrap(),
        gpu.read(b.vals[out].elems::<u32>(0, n)).unwrap(),
    )
}

fn gpu_sort_u64(
    gpu: &TestGpu,
    sort: &RadixSort,
    b: &SortBuffers,
    keys: &[u64],
    bits: u32,
) -> (Vec<u64>, Vec<u32>) {
    let n = keys.len() as u64;
    let vals: Vec<u32> = (0..n as u32).collect();
    for i in 0..2 {
        testing::fill_noise(gpu, &b.keys[i], 30 + i as u64);
        testing::fill_noise(gpu, &b.vals[i], 40 + i as u64);
    }
    gpu.upload(b.keys[0].all(), keys).unwrap();
    gpu.upload(b.vals[0].all(), &vals).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    let out = sort.record(&mut rec, b, Count::Host(n as u32), bits);
    rec.finish().unwrap();
    (
        gpu.read(b.keys[out].elems::<u64>(0, n)).unwrap(),
        gpu.read(b.vals[out].elems::<u32>(0, n)).unwrap(),
    )
}

/// The sort in each shape (both must give the twin's order), announced on stderr so a failure
/// names its shape.
fn sorts(gpu: &TestGpu) -> impl Iterator<Item = RadixSort> + '_ {
    SortShape::ALL.iter().map(|&shape| {
        eprintln!("radix sort shape: {}", shape.name());
        RadixSort::with_shape(gpu, shape).unwrap()
    })
}

fn check<K: PartialEq + std::fmt::Debug>(
    what: &str,
    got: (Vec<K>, Vec<u32>),
    want: (Vec<K>, Vec<u32>),
) {
    assert_eq!(got.0.len(), want.0.len(), "{what}: length");
    if let Some(p) = got.0.iter().zip(&want.0).position(|(a, b)| a != b) {
        panic!(
            "{what}: key mismatch at {p}: got {:?}, want {:?}",
            got.0[p], want.0[p]
        );
    }
    // Values are the original indices: equal values prove the order of equal keys (stability).
    if let Some(p) = got.1.iter().zip(&want.1).position(|(a, b)| a != b) {
        panic!(
            "{what}: value (stability) mismatch at {p}: got {}, want {}",
            got.1[p], want.1[p]
        );
    }
}

fn sizes() -> Vec<u32> {
    let mut s = vec![0, 1, 7, 255, 256, 257, 2047, 2048, 2049];
    for k in [12u32, 16] {
        s.extend([(1 << k) - 1, 1 << k, (1 << k) + 1]);
    }
    s
}

#[test]
fn u32_random_keys_all_sizes() {
    let gpu = testing::gpu();
    for sort in sorts(&gpu) {
        let b = sort
            .buffers(&gpu, "test", (1 << 16) + 1, KeyWidth::U32)
            .unwrap();
        for &n in &sizes() {
            let keys = Noise::new(n as u64).u32s(n as usize);
            check(
                &format!("n={n}"),
                gpu_sort_u32(&gpu, &sort, &b, &keys, 32),
                sort_pairs_u32(&keys, &(0..n).collect::<Vec<_>>(), 32),
            );
        }
    }
}

#[test]
fn u32_large_2_pow_22_plus_one() {
    let gpu = testing::gpu();
    // The subgroup-size re-runs sort 2^20 + 1: 513 blocks, whose 16-digit histogram (8 208
    // counts) still needs the scan's second level and ends in a one-key block, as at 2^22 + 1;
    // a quarter of the keys, for lane counts, not sizes.
    let n = if testing::subgroup_rerun() {
        (1u32 << 20) + 1
    } else {
        (1u32 << 22) + 1
    };
    for sort in sorts(&gpu) {
        let b = sort.buffers(&gpu, "test", n, KeyWidth::U32).unwrap();
        // Tile-id shaped keys (few distinct high parts, many ties) at 2^22 + 1 elements.
        let mut noise = Noise::new(7);
        let keys: Vec<u32> = (0..n)
            .map(|_| ((noise.next_u32() % 300) << 16) | (noise.next_u32() & 0xffff))
            .collect();
        let vals: Vec<u32> = (0..n).collect();
        check(
            &format!("{n} tile-shaped keys, 26 bits"),
            gpu_sort_u32(&gpu, &sort, &b, &keys, 26),
            sort_pairs_u32(&keys, &vals, 26),
        );
    }
}

#[test]
fn u32_patterns() {
    let gpu = testing::gpu();
    for sort in sorts(&gpu) {
        let n = 5000u32;
        let b = sort.buffers(&gpu, "test", n, KeyWidth::U32).unwrap();
        let vals: Vec<u32> = (0..n).collect();
        let cases: Vec<(&str, Vec<u32>)> = vec![
            ("all equal", vec![0xdead_beef; n as usize]),
            ("all zero", vec![0; n as usize]),
            ("sorted", (0..n).collect()),
            ("reverse sorted", (0..n).rev().collect()),
            (
                "only the top bit",
                (0..n)
                    .map(|i| if i % 3 == 0 { 0x8000_0000 } else { 0 })
                    .collect(),
            ),
            (
                "max and zero",
                (0..n)
                    .map(|i| if i % 2 == 0 { u32::MAX } else { 0 })
                    .collect(),
            ),
            (
                "few distinct",
                Noise::new(5)
                    .u32s(n as usize)
                    .iter()
                    .map(|x| x % 4)
                    .collect(),
            ),
        ];
        for (what, keys) in cases {
            check(
                what,
                gpu_sort_u32(&gpu, &sort, &b, &keys, 32),
                sort_pairs_u32(&keys, &vals, 32),
            );
        }
    }
}

#[test]
fn u32_partial_bits_ignore_high_bits() {
    let gpu = testing::gpu();
    for sort in sorts(&gpu) {
        let n = 10_000u32;
        let b = sort.buffers(&gpu, "test", n, KeyWidth::U32).unwrap();
        let keys = Noise::new(11).u32s(n as usize);
        let vals: Vec<u32> = (0..n).collect();
        for bits in [0, 1, 3, 4, 5, 13, 18, 31] {
            check(
                &format!("bits={bits}"),
                gpu_sort_u32(&gpu, &sort, &b, &keys, bits),
                sort_pairs_u32(&keys, &vals, bits),
            );
        }
    }
}

#[test]
fn u64_keys() {
    let gpu = testing::gpu();
    for sort in sorts(&gpu) {
        let cap = 70_001u32;
        let b = sort.buffers(&gpu, "test", cap, KeyWidth::U64).unwrap();
        for &n in &[0u32, 1, 7, 2049, 70_001] {
            let keys = Noise::new(100 + n as u64).u64s(n as usize);
            let vals: Vec<u32> = (0..n).collect();
            check(
                &format!("u64 n={n}"),
                gpu_sort_u64(&gpu, &sort, &b, &keys, 64),
                sort_pairs_u64(&keys, &vals, 64),
            );
        }
        let n = 9000u32;
        let vals: Vec<u32> = (0..n).collect();
        // (tile << 32 | depth bits) as the rasteriser builds them, and the bit limits.
        let mut noise = Noise::new(3);
        let tile_depth: Vec<u64> = (0..n)
            .map(|_| ((noise.next_u64() % 1200) << 32) | noise.next_u32() as u64)
            .collect();
        check(
            "tile|depth 43 bits",
            gpu_sort_u64(&gpu, &sort, &b, &tile_depth, 43),
            sort_pairs_u64(&tile_depth, &vals, 43),
        );
        let top: Vec<u64> = (0..n as u64)
            .map(|i| if i % 5 == 0 { 1 << 63 } else { i << 40 })
            .collect();
        check(
            "top bit of u64",
            gpu_sort_u64(&gpu, &sort, &b, &top, 64),
            sort_pairs_u64(&top, &vals, 64),
        );
        let edge: Vec<u64> = (0..n as u64)
            .map(|i| [u64::MAX, 0, 1 << 32, (1 << 32) - 1][(i % 4) as usize])
            .collect();
        check(
            "word edges",
            gpu_sort_u64(&gpu, &sort, &b, &edge, 64),
            sort_pairs_u64(&edge, &vals, 64),
        );
    }
}

#[test]
fn count_from_gpu_buffer() {
    // The count is produced on the GPU (here: copied from a buffer) and the sort must use it
    // without the host knowing it: elements past the count stay untouched.
    let gpu = testing::gpu();
    for sort in sorts(&gpu) {
        let cap = 10_000u32;
        let b = sort.buffers(&gpu, "test", cap, KeyWidth::U32).unwrap();
        let keys = Noise::new(1).u32s(cap as usize);
        let vals: Vec<u32> = (0..cap).collect();
        gpu.upload(b.keys[0].all(), &keys).unwrap();
        gpu.upload(b.vals[0].all(), &vals).unwrap();
        testing::fill_noise(&gpu, &b.keys[1], 5);
        let counts = gpu.buffer_from("counts", &[0u32; 64]).unwrap();
        let n = 6789u32;
        let src = gpu.buffer_from("count source", &[n]).unwrap();
        let mut rec = Recorder::new(&gpu).unwrap();
        rec.copy(src.slice(0, 4), counts.slice(0, 4));
        let out = sort.record(&mut rec, &b, Count::Gpu(counts.slice(0, 4)), 32);
        rec.finish().unwrap();
        let got_k: Vec<u32> = gpu.read(b.keys[out].elems::<u32>(0, n as u64)).unwrap();
        let got_v: Vec<u32> = gpu.read(b.vals[out].elems::<u32>(0, n as u64)).unwrap();
        check(
            "gpu count",
            (got_k, got_v),
            sort_pairs_u32(&keys[..n as usize], &vals[..n as usize], 32),
        );
    }
}

#[test]
fn capacity_errors_are_reported() {
    let gpu = testing::gpu();
    let sort = RadixSort::new(&gpu).unwrap();
    // Beyond one binding's range (lavapipe: 128 MiB) the sort refuses with a message, not a crash.
    let too_big = (gpu.info.max_storage_buffer_range / 8).saturating_add(1);
    match sort.buffers(&gpu, "huge", too_big, KeyWidth::U64) {
        Err(e) => assert!(e.to_string().contains("capacity"), "{e}"),
        Ok(_) => panic!("a sort of {too_big} u64 keys should exceed one binding"),
    }
}

dispflow_vk::subgroup_reruns!();
