// What the correctly rounded square root (lib/sqrt_rn.glsl) and quotient (lib/div_rn.glsl)
// share: the exact comparison of A 2^shift (A < 2^24) with a 64-bit product (p_hi, p_lo), and
// the float32 neighbours of a positive float.
// Twin: none (integer helpers; NumPy's float32 sqrt and division are their users' twins).

// Whether A 2^shift < p_hi 2^32 + p_lo, where the product is at least 2^24 and below 2^64.
bool shifted_below(uint big_a, int shift, uint p_hi, uint p_lo) {
    if (shift < 0) return true;                  // A 2^shift < 2^24 <= the product
    if (shift > 40) return false;                // A 2^shift >= 2^64 > the product
    uint a_hi, a_lo;
    if (shift >= 32) {
        a_hi = big_a << uint(shift - 32);
        a_lo = 0u;
    } else {
        a_hi = shift == 0 ? 0u : big_a >> uint(32 - shift);
        a_lo = big_a << uint(shift);
    }
    return a_hi < p_hi || (a_hi == p_hi && a_lo < p_lo);
}

float next_up(float s) { return uintBitsToFloat(floatBitsToUint(s) + 1u); }
float next_down(float s) { return uintBitsToFloat(floatBitsToUint(s) - 1u); }
