// Key access for the radix sort, u32 or u64 keys (KEY64 defined by the including stage).
#ifndef RADIX_COMMON_GLSL
#define RADIX_COMMON_GLSL

#ifdef KEY64
#define KEY_T uvec2 // (low word, high word)
#else
#define KEY_T uint
#endif

// 4-bit digit at `shift` (a multiple of 4, so a digit never straddles the two words).
uint key_digit(KEY_T k, uint shift, uint mask) {
#ifdef KEY64
    uint w = shift < 32u ? (k.x >> shift) : (k.y >> (shift - 32u));
#else
    uint w = k >> shift;
#endif
    return w & mask;
}

#endif
