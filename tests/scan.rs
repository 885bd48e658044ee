//! Prefix sum: GPU vs the CPU twin, host and GPU-resident counts, sizes around block edges.

use dispflow_vk::kernels::scan::{Count, PrefixSum};
use dispflow_vk::reference;
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

fn sizes() -> Vec<u32> {
    let mut s = vec![0, 1, 7, 255, 256, 257, 2047, 2048, 2049, 4095, 4096, 4097];
    for k in [12u32, 16, 22] {
        s.extend([(1 << k) - 1, 1 << k, (1 << k) + 1]);
    }
    s.push(2048 * 2048 + 5); // three pyramid levels
    s
}

#[test]
fn scan_matches_reference() {
    let gpu = testing::gpu();
    let scan = PrefixSum::new(&gpu).unwrap();
    for (i, &n) in sizes().iter().enumerate() {
        // Small values keep partial sums informative; one case uses full-range values (wrap-around).
        let mut noise = Noise::new(i as u64);
        let input: Vec<u32> = if n == 4097 {
            noise.u32s(n as usize)
        } else {
            noise.u32s(n as usize).iter().map(|x| x % 1000).collect()
        };
        let cap = n.max(1);
        let scratch = scan.scratch(&gpu, cap).unwrap();
        let inp = gpu.buffer("scan input", cap as u64 * 4).unwrap();
        let out = gpu.buffer("scan output", cap as u64 * 4).unwrap();
        testing::fill_noise(&gpu, &out, 99);
        gpu.upload(inp.all(), &input).unwrap();
        let mut rec = Recorder::new(&gpu).unwrap();
        scan.record(&mut rec, &scratch, inp.all(), out.all(), Count::Host(n));
        rec.finish().unwrap();
        let got: Vec<u32> = gpu.read(out.elems::<u32>(0, n as u64)).unwrap();
        let want = reference::scan::exclusive_scan(&input);
        assert_eq!(got.len(), want.len());
        if let Some(p) = got.iter().zip(&want).position(|(a, b)| a != b) {
            panic!(
                "n = {n}: first mismatch at {p}: got {}, want {}",
                got[p], want[p]
            );
        }
    }
}

dispflow_vk::subgroup_reruns!();
