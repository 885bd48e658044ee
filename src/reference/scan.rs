//! Twin of `glsl/scan/*`: exclusive prefix sum with u32 wrap-around (as the GPU adds).

/// `out[i] = input[0] + … + input[i-1]` (mod 2^32).
pub fn exclusive_scan(input: &[u32]) -> Vec<u32> {
    let mut acc = 0u32;
    input
        .iter()
        .map(|&x| {
            let e = acc;
            acc = acc.wrapping_add(x);
            e
        })
        .collect()
}
