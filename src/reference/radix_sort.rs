//! Twin of `glsl/sort/*`: a stable sort of (key, value) pairs by the low `bits` bits of the key.
//! Deliberately not a radix sort, so the two cannot share an algorithmic mistake.

fn mask(bits: u32) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

/// Stable sort by `key & (2^bits − 1)`; keys keep their high bits in the output.
pub fn sort_pairs_u64(keys: &[u64], vals: &[u32], bits: u32) -> (Vec<u64>, Vec<u32>) {
    assert_eq!(keys.len(), vals.len());
    let m = mask(bits);
    let mut idx: Vec<usize> = (0..keys.len()).collect();
    idx.sort_by_key(|&i| keys[i] & m); // slice::sort_by_key is stable
    (
        idx.iter().map(|&i| keys[i]).collect(),
        idx.iter().map(|&i| vals[i]).collect(),
    )
}

/// As [`sort_pairs_u64`] for u32 keys.
pub fn sort_pairs_u32(keys: &[u32], vals: &[u32], bits: u32) -> (Vec<u32>, Vec<u32>) {
    let wide: Vec<u64> = keys.iter().map(|&k| k as u64).collect();
    let (k, v) = sort_pairs_u64(&wide, vals, bits.min(32));
    (k.into_iter().map(|k| k as u32).collect(), v)
}
