// Positional encoding γ with an exact phase reduction.
//
// sin(2^j v) in f32 loses the phase for large arguments (GLSL's sin is only specified on
// [−π, π]; 2^9·1e4 = 5e6 rad has an f32 spacing of 0.5 rad). Here v·2^j/(2π) is split into
// products that are exact in f32: v = vh + vl (12 significant bits each) and 1/(2π) =
// HI + MID + LO (12, 12, 24 bits), so vh·HI, vh·MID, vl·HI, vl·MID are exact, scaling by 2^j is
// exact, and each fract() is exact; only vh·LO + vl·LO rounds (relative 2^−24 of a term ~2^−24·v·2^j).
// The phase in turns is then accurate to ~1e-7 + 4e-16·|v|·2^j (~1e-7 for |v| ≤ 1e5 at L = 10),
// so the encoding error is that of the device's sin/cos on [−π, π] (lavapipe: ≤ 2.3e-6),
// independent of the frequency. Valid range: |v| ≤ 1e5 at full accuracy; beyond, the phase
// error grows as 4e-16·2^j·|v| turns (L = 10: 1e-3 rad at |v| = 1e9) but the result stays
// finite for every finite v. Inf/NaN give NaN.
#ifndef POSENC_GLSL
#define POSENC_GLSL

// sin and cos of v·2^j.
vec2 sincos_pow2(float v, int j) {
    const float HI = uintBitsToFloat(0x3e22f000u);
    const float MID = uintBitsToFloat(0x38183000u);
    const float LO = uintBitsToFloat(0x31dc9c88u);
    precise float vh = uintBitsToFloat(floatBitsToUint(v) & 0xFFFFF000u);
    precise float vl = v - vh;
    precise float t0 = fract(ldexp(vh * HI, j));
    precise float t1 = fract(ldexp(vh * MID, j));
    precise float t2 = fract(ldexp(vl * HI, j));
    precise float t3 = fract(ldexp(vl * MID, j));
    precise float t4 = fract(ldexp(vh * LO + vl * LO, j));
    precise float turns = fract(fract(t0 + t1) + fract(t2 + t3) + t4);
    precise float a = 6.28318530717958647 * (turns - round(turns)); // in [−π, π]
    return vec2(sin(a), cos(a));
}

#endif
